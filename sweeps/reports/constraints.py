"""The summary's table per constraint, for a sweep whose trials hold several constraints apart
(docs/constraints.md): per configuration and constraint, the cost's mean with its t-interval, the
limit, and the seeds within it with P(feasible)'s Wilson interval; then the seeds within every
limit, the joint rule the verdicts use (sweeps/score.py: a trial's cost is max_k (J_k − b_k) held
to 0). Each interval is verdicts.py's, whose coverage its simulation tests measure."""

from __future__ import annotations

import math

import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, per_constraint
from sweeps.reports.configurations import KEYS
from sweeps.reports.verdicts import feasible_seeds, mean_interval, proportion_interval


def constraint_names(trials: pd.DataFrame) -> list[str]:
    """The constraints the trials hold apart (their ``cost_limit/NAME`` columns), in column order."""
    prefix = f"{COST_LIMIT}/"
    return [c[len(prefix):] for c in trials.columns if c.startswith(prefix)]


def constraints_table(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per configuration and constraint (and one per configuration for them all, ``joint``)
    of the finished trials; empty without several constraints."""
    names = constraint_names(trials)
    if len(names) < 2:
        return pd.DataFrame()
    done = trials[trials["status"].astype(str).eq("TERMINATED")] if "status" in trials else trials
    rows = []
    for key, g in done.groupby(KEYS, dropna=False, sort=True):
        for name in names:
            costs = pd.to_numeric(g[per_constraint(EPISODE_COST, name)], errors="coerce")
            limit = float(pd.to_numeric(g[per_constraint(COST_LIMIT, name)], errors="coerce").median())
            mean, low, high = mean_interval(costs)
            k, n = feasible_seeds(costs, limit)
            p, p_low, p_high = proportion_interval(k, n)
            rows.append({**dict(zip(KEYS, key)), "constraint": name, "cost_mean": mean, "cost_low": low,
                         "cost_high": high, "cost_limit": limit, "feasible_seeds": k, "seeds": n,
                         "p_feasible": p, "p_feasible_low": p_low, "p_feasible_high": p_high})
        joint = pd.to_numeric(g[EPISODE_COST], errors="coerce")  # max_k (J_k − b_k), held to 0
        k, n = feasible_seeds(joint, 0.0)
        p, p_low, p_high = proportion_interval(k, n)
        rows.append({**dict(zip(KEYS, key)), "constraint": "joint", "cost_mean": math.nan, "cost_low": math.nan,
                     "cost_high": math.nan, "cost_limit": math.nan, "feasible_seeds": k, "seeds": n,
                     "p_feasible": p, "p_feasible_low": p_low, "p_feasible_high": p_high})
    return pd.DataFrame(rows)


def _interval(mean: float, low: float, high: float, fmt: str = ".2f") -> str:
    if math.isnan(mean):
        return "–"
    return f"{mean:{fmt}}" + ("" if math.isnan(low) else f" [{low:{fmt}}, {high:{fmt}}]")


def constraints_markdown(trials: pd.DataFrame) -> str:
    """:func:`constraints_table` as markdown, with a line on what it shows; '' without several constraints."""
    table = constraints_table(trials)
    if table.empty:
        return ""
    lines = ["**Per constraint** (cost: mean over seeds [95% t-interval]; P(feasible): seeds within the limit "
             "[Wilson 95%]; `joint`: seeds within every limit, the rule the verdicts use)", "",
             "| configuration | task | constraint | cost | limit | feasible seeds | P(feasible) |",
             "|---|---|---|---:|---:|---:|---:|"]
    for _, r in table.iterrows():
        limit = "–" if math.isnan(r["cost_limit"]) else f"{r['cost_limit']:g}"
        lines.append(f"| {r['config']} | {r['task']} | {r['constraint']} | "
                     f"{_interval(r['cost_mean'], r['cost_low'], r['cost_high'])} | {limit} | "
                     f"{r['feasible_seeds']}/{r['seeds']} | "
                     f"{_interval(r['p_feasible'], r['p_feasible_low'], r['p_feasible_high'])} |")
    return "\n".join(lines) + "\n"
