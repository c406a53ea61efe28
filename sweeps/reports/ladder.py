"""The report across a ladder of cost limits, against the fixed-multiplier frontier.

Spoor et al. ("Lagrangian methods in safe RL", 2026) show that a verdict at one cost limit can
reverse at another, and that automatic multiplier updates are never compared with the empirical
optimum: the return-cost front traced by runs at fixed multipliers. Per task, from the trials of a
ladder sweep (``cost_limits``: each configuration × limit × seed a trial) and, where it ran, its
frontier (``frontier``: an algorithm at fixed ν values, group ``frontier``):

- the frontier's points: per fixed ν, the mean return and mean cost over its seeds, the return's
  interval; R*(b) = the best mean return among the points with mean cost ≤ b, with that point's
  interval (NaN where no point is within b);
- per configuration and limit: its return with its interval, P(feasible) over its seeds (Wilson),
  its regret R*(b) − R(b) (its interval from both ends: R*'s low minus R's high, and so on), its
  rank at b: the configurations within b by mean cost, by return, then the others by cost;
- where the ranking changes between consecutive limits, and each configuration's wins: first at k
  of the n limits;
- the worst and the mean regret over the ladder, by which confirmation may choose its winners.

Tasks are never ranked together: every table is per task.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, EPISODE_RETURN
from sweeps.reports.configurations import fmt_num, fmt_value, is_na, metric_name, prepared, text_column
from sweeps.reports.safety import wilson_interval
from sweeps.reports.stats import interval

#: The group of a sweep's fixed-multiplier runs, and the field they fix.
FRONTIER_GROUP, FRONTIER_FIELD = "frontier", "nu_fixed"
#: A configuration across the ladder (its limit aside).
CONFIG_KEYS = ["task", "group", "param", "value", "algo"]
#: How confirmation may pick its winners over a ladder (sweeps/reports/confirm.py).
REGRET_CHOICES = ("worst", "mean")


def _scored(trials: pd.DataFrame) -> pd.DataFrame:
    df, failed = prepared(trials)
    df = df[~failed & ~df["status"].astype(str).eq("STOPPED")].copy()
    for col in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT):
        df[col] = pd.to_numeric(df[col], errors="coerce")
    df["algo"] = text_column(df, "algo")
    df["value"] = df["value"].map(lambda v: "" if is_na(v) else fmt_value(v))
    return df


def frontier_points(trials: pd.DataFrame) -> pd.DataFrame:
    """Per task and fixed ν: seeds, mean return (with its interval) and mean cost."""
    df = _scored(trials)
    df = df[df["group"].astype(str).eq(FRONTIER_GROUP)]
    rows = []
    for (task, algo, nu), g in df.groupby(["task", "algo", "value"], sort=False):
        ret, ret_low, ret_high = interval(g[EPISODE_RETURN])
        rows.append({"task": task, "algo": algo, "nu": nu, "n_seeds": len(g), "return_mean": ret,
                     "return_low": ret_low, "return_high": ret_high, "cost_mean": g[EPISODE_COST].mean()})
    return pd.DataFrame(rows, columns=["task", "algo", "nu", "n_seeds", "return_mean", "return_low", "return_high",
                                       "cost_mean"])


def best_within(points: pd.DataFrame, limit: float) -> dict:
    """R*(b): the point of the best mean return among those with mean cost ≤ ``limit``."""
    inside = points[points["cost_mean"] <= limit]
    if inside.empty:
        return {"r_star": math.nan, "r_star_low": math.nan, "r_star_high": math.nan, "r_star_nu": ""}
    best = inside.loc[inside["return_mean"].idxmax()]
    return {"r_star": best["return_mean"], "r_star_low": best["return_low"], "r_star_high": best["return_high"],
            "r_star_nu": best["nu"]}


def rank_at_limit(rows: pd.DataFrame) -> pd.Series:
    """1 = best: within the limit by mean cost first (by return, high first), then the others (by
    cost, low first); ties share the order they come in."""
    within = rows["cost_mean"] <= rows[COST_LIMIT]
    key = pd.DataFrame({"out": ~within, "by": np.where(within, -rows["return_mean"], rows["cost_mean"])},
                       index=rows.index)
    order = key.sort_values(["out", "by"], kind="stable").index
    return pd.Series(range(1, len(order) + 1), index=order).reindex(rows.index)


def ladder_table(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per task, configuration and limit (the frontier's runs aside): the module
    docstring's figures."""
    df = _scored(trials)
    points = frontier_points(trials)
    df = df[~df["group"].astype(str).eq(FRONTIER_GROUP)]
    rows = []
    for key, g in df.groupby([*CONFIG_KEYS, COST_LIMIT], sort=False):
        limit = float(key[-1])
        ret, ret_low, ret_high = interval(g[EPISODE_RETURN])
        n, k = len(g), int((g[EPISODE_COST] <= limit).sum())
        p, p_low, p_high = wilson_interval(k, n)
        star = best_within(points[points["task"] == key[0]], limit)
        rows.append({**dict(zip([*CONFIG_KEYS, COST_LIMIT], key)), "n_seeds": n, "return_mean": ret,
                     "return_low": ret_low, "return_high": ret_high, "cost_mean": g[EPISODE_COST].mean(),
                     "p_feasible": p, "p_feasible_low": p_low, "p_feasible_high": p_high, **star,
                     "regret": star["r_star"] - ret, "regret_low": star["r_star_low"] - ret_high,
                     "regret_high": star["r_star_high"] - ret_low})
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    table["rank"] = 0
    for _, g in table.groupby(["task", COST_LIMIT], sort=False):
        table.loc[g.index, "rank"] = rank_at_limit(g)
    return table.sort_values(["task", COST_LIMIT, "rank"], kind="stable").reset_index(drop=True)


def label(row) -> str:
    """A configuration's name across the ladder: its algorithm, group and swept value."""
    parts = [str(row["algo"]), "" if str(row["group"]) in ("", "paper", "compare") else str(row["group"])]
    if str(row["param"]) and str(row["param"]) != "algo":
        parts.append(f"{row['param']}={row['value']}")
    return " ".join(p for p in parts if p)


def wins(table: pd.DataFrame) -> pd.DataFrame:
    """Per task and configuration: first at k of the n limits, and the worst and mean regret over them."""
    rows = []
    for (task, name), g in table.assign(name=table.apply(label, axis=1)).groupby(["task", "name"], sort=False):
        regret = g["regret"].to_numpy(dtype=float)
        rows.append({"task": task, "configuration": name, "wins": int((g["rank"] == 1).sum()),
                     "limits": g[COST_LIMIT].nunique(),
                     "worst_regret": float(np.max(regret)) if np.isfinite(regret).all() and len(regret) else math.nan,
                     "mean_regret": float(np.mean(regret)) if np.isfinite(regret).all() and len(regret) else math.nan})
    return pd.DataFrame(rows, columns=["task", "configuration", "wins", "limits", "worst_regret", "mean_regret"])


def ranking_changes(table: pd.DataFrame) -> list[str]:
    """One line per pair of consecutive limits of a task whose ranking differs."""
    lines = []
    for task, t in table.groupby("task", sort=False):
        orders = [(b, [label(r) for _, r in g.sort_values("rank").iterrows()])
                  for b, g in t.groupby(COST_LIMIT, sort=True)]
        for (b0, o0), (b1, o1) in zip(orders, orders[1:]):
            if o0 != o1:
                lines.append(f"{task}: b = {fmt_value(b0)} → {fmt_value(b1)}: {' > '.join(o0)} becomes "
                             f"{' > '.join(o1)}")
    return lines


def configs_by_label(trials: pd.DataFrame) -> dict[str, list[str]]:
    """Each configuration's name across the ladder (:func:`label`) → its trials' ``config`` labels
    (one per limit), the frontier's runs aside: how a name :func:`choose` returns finds its fields."""
    df = _scored(trials)
    df = df[~df["group"].astype(str).eq(FRONTIER_GROUP)]
    out: dict[str, list[str]] = {}
    for name, config in zip(df.apply(label, axis=1), df["config"].astype(str)):
        out.setdefault(name, [])
        if config not in out[name]:
            out[name].append(config)
    return out


def choose(table: pd.DataFrame, k: int, by: str = "worst") -> list[str]:
    """The ``k`` configurations of least ``by`` regret over the ladder (``by``: worst | mean), per task."""
    if by not in REGRET_CHOICES:
        raise ValueError(f"regret choice {by!r}; accepted: {' | '.join(REGRET_CHOICES)}")
    w = wins(table).dropna(subset=[f"{by}_regret"])
    return [c for _, g in w.groupby("task", sort=False) for c in g.nsmallest(k, f"{by}_regret")["configuration"]]


def _ci(point, low, high) -> str:
    if is_na(point):
        return "–"
    return fmt_num(point) if is_na(low) else f"{fmt_num(point)} [{fmt_num(low)}, {fmt_num(high)}]"


def ladder_markdown(table: pd.DataFrame) -> str:
    """The per-limit tables, the wins and worst regrets, and where the ranking changes."""
    if table.empty:
        return ""
    out = ["## Across the ladder of cost limits", ""]
    for task, t in table.groupby("task", sort=False):
        out += [f"### {task}", "", "| b | rank | configuration | seeds | return [95% CI] | cost | P(feasible) "
                "[Wilson] | R*(b) (ν) | regret [CI] |", "|---|---|---|---|---|---|---|---|---|"]
        for _, r in t.iterrows():
            star = "–" if is_na(r["r_star"]) else f"{fmt_num(r['r_star'])} (ν={r['r_star_nu']})"
            out.append(f"| {fmt_value(r[COST_LIMIT])} | {int(r['rank'])} | {label(r)} | {int(r['n_seeds'])} | "
                       f"{_ci(r['return_mean'], r['return_low'], r['return_high'])} | {fmt_num(r['cost_mean'])} | "
                       f"{_ci(r['p_feasible'], r['p_feasible_low'], r['p_feasible_high'])} | {star} | "
                       f"{_ci(r['regret'], r['regret_low'], r['regret_high'])} |")
        w = wins(t)
        out += ["", "| configuration | first at | worst regret | mean regret |", "|---|---|---|---|"]
        out += [f"| {r.configuration} | {r.wins} of {r.limits} | {fmt_num(r.worst_regret)} | {fmt_num(r.mean_regret)} |"
                for r in w.itertuples()]
        changes = [f"- ranking changes at {c.split(': ', 1)[1]}" for c in ranking_changes(t)]
        out += ["", *(changes or ["- the ranking is the same at every limit"]), ""]
    return "\n".join(out)


def ladder_png(table: pd.DataFrame, points: pd.DataFrame, path) -> str | None:
    """Return and cost against b per configuration (one column per task), R*(b) and the line
    cost = b drawn."""
    if table.empty:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(table["task"]))
    fig, axes = plt.subplots(2, len(tasks), figsize=(5 * len(tasks), 7), squeeze=False)
    for j, task in enumerate(tasks):
        t = table[table["task"] == task]
        limits = np.sort(t[COST_LIMIT].unique())
        for name, g in t.assign(name=t.apply(label, axis=1)).groupby("name", sort=False):
            g = g.sort_values(COST_LIMIT)
            axes[0, j].errorbar(g[COST_LIMIT], g["return_mean"], yerr=[g["return_mean"] - g["return_low"],
                                g["return_high"] - g["return_mean"]], marker="o", capsize=3, label=name)
            axes[1, j].plot(g[COST_LIMIT], g["cost_mean"], marker="o", label=name)
        star = [best_within(points[points["task"] == task], b)["r_star"] for b in limits]
        if np.isfinite(star).any():
            axes[0, j].step(limits, star, where="post", color="black", linestyle="--", label="R*(b), fixed ν")
        axes[1, j].plot(limits, limits, color="grey", linestyle=":", label="cost = b")
        axes[0, j].set(title=task, ylabel="return")
        axes[1, j].set(xlabel="cost limit b", ylabel="cost")
        axes[0, j].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return str(path)


def applies(trials: pd.DataFrame) -> bool:
    """Whether a sweep's trials hold a ladder (several limits on one task) or a frontier."""
    if trials.empty:
        return False
    limits = pd.to_numeric(trials[COST_LIMIT], errors="coerce")
    frontier = trials["group"].astype(str).eq(FRONTIER_GROUP)
    several = limits[~frontier].groupby(trials.loc[~frontier, "task"]).nunique().gt(1).any()
    return bool(frontier.any() or several)


def parent_metrics(table: pd.DataFrame) -> dict[str, float]:
    """What the parent run carries per configuration: its wins over the ladder and its worst regret
    (MLflow's runs table sorts sweeps by them); the task leads the name where there are several."""
    w = wins(table)
    several = w["task"].nunique() > 1
    out = {}
    for r in w.itertuples():
        name = metric_name(f"{r.task}/{r.configuration}" if several else r.configuration)
        out[f"ladder_wins/{name}"] = float(r.wins)
        if math.isfinite(r.worst_regret):
            out[f"ladder_worst_regret/{name}"] = float(r.worst_regret)
    return out


def write_ladder_report(trials: pd.DataFrame, out_dir) -> tuple[str, dict[str, float]]:
    """``ladder.csv``, ``ladder.md`` and ``ladder.png`` (the figures, the tables, the plot) and the
    frontier's points in ``frontier_points.csv``; returns the markdown and the parent's metrics."""
    from pathlib import Path

    out = Path(out_dir)
    table = ladder_table(trials)
    points = frontier_points(trials)
    table.to_csv(out / "ladder.csv", index=False)
    points.to_csv(out / "frontier_points.csv", index=False)
    text = ladder_markdown(table)
    (out / "ladder.md").write_text(text + "\n", encoding="utf-8")
    ladder_png(table, points, out / "ladder.png")
    return text, parent_metrics(table) if not table.empty else {}


def by_limit(trials: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """The trials a table is made of, per limit of a ladder: [(``table-bB``, that limit's trials,
    the frontier's left out)], so the paper's layout (one configuration per task and algorithm)
    holds at each; without a ladder [("", trials)]."""
    frontier = trials["group"].astype(str).eq(FRONTIER_GROUP)
    limits = pd.to_numeric(trials[COST_LIMIT], errors="coerce")
    if not applies(trials) or limits[~frontier].nunique() < 2:
        return [("", trials[~frontier] if frontier.any() else trials)]
    return [(f"table-b{fmt_value(b)}", trials[~frontier & (limits == b)]) for b in sorted(limits[~frontier].unique())]
