"""The report of a tuned comparison (sweeps/tuned.py): what tuning changed, per algorithm.

On the confirmation's fresh seeds, for each algorithm:

- **default against tuned**: both scores with their intervals, the gap tuned − default in mean return
  with a bootstrap interval (seeds resampled on each side) and P(improvement), the chance a tuned seed
  beats a default one (stats.probability_of_improvement);
- **the winner's curse**: the winner's score on the search's seeds minus its score on the fresh ones
  (a search's best is the best of many noisy draws: its search score is biased upward);
- **sensitivity**: how far the search's configurations spread. Adkins, Bowling & White (NeurIPS 2024)
  measure it for return as the gap between tuned and a fixed choice; within one task we give, for
  return and cost, the best configuration's mean minus the median configuration's and the
  interquartile range of the configurations' means, and for feasibility the share of configurations
  feasible on average and the range of their seeds' feasible fractions;
- **the ranking** of the tuned algorithms on the fresh seeds (feasible on average first, then by
  return) beside the ranking of their defaults on the same seeds, and whether tuning changed it.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import EPISODE_COST, EPISODE_RETURN, FEASIBLE
from sweeps.reports.configurations import fmt_num
from sweeps.reports.stats import CONFIDENCE, REPS, SEED, interval, probability_of_improvement

#: How the confirmation labels its groups: ``ALGO-tuned1`` (the search's best, then the next) and
#: ``ALGO-default`` (sweeps/tuned.py writes them, this report reads them).
TUNED, DEFAULT = "tuned", "default"


def gap_interval(tuned, default) -> tuple[float, float, float]:
    """(mean(tuned) − mean(default), CI low, CI high): a percentile bootstrap resampling each side's
    seeds independently; NaN ends with fewer than 2 seeds on a side."""
    a, b = (np.asarray(x, dtype=float) for x in (tuned, default))
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if not a.size or not b.size:
        return math.nan, math.nan, math.nan
    point = float(a.mean() - b.mean())
    if a.size < 2 or b.size < 2:
        return point, math.nan, math.nan
    rng = np.random.default_rng(SEED)
    draws = (rng.choice(a, (REPS, a.size)).mean(axis=1) - rng.choice(b, (REPS, b.size)).mean(axis=1))
    tail = (1 - CONFIDENCE) / 2
    return point, float(np.quantile(draws, tail)), float(np.quantile(draws, 1 - tail))


def winners_curse(search_return: float, fresh_return: float) -> float:
    """The winner's score on the search's seeds minus its score on fresh ones (> 0: it was flattered)."""
    return float(search_return - fresh_return)


def sensitivity(summary: pd.DataFrame) -> dict:
    """How much return, cost and feasibility move across a search's configurations (``summary``: one
    row per configuration, sweeps/reports/report.py ``summarize``)."""
    done = summary[summary["n_seeds"] > 0]
    out = {"configurations": int(len(done))}
    for name, col, best in (("return", "return_mean", max), ("cost", "cost_mean", min)):
        x = pd.to_numeric(done[col], errors="coerce").dropna().to_numpy()
        if not x.size:
            out |= {f"{name}_best_minus_median": math.nan, f"{name}_iqr": math.nan}
            continue
        q1, med, q3 = np.quantile(x, [0.25, 0.5, 0.75])
        out |= {f"{name}_best_minus_median": float(best(x) - med), f"{name}_iqr": float(q3 - q1)}
    frac = pd.to_numeric(done["feasible_fraction"], errors="coerce").dropna()
    out |= {"feasible_share": float(done["mean_feasible"].astype(bool).mean()) if len(done) else math.nan,
            "feasible_fraction_min": float(frac.min()) if len(frac) else math.nan,
            "feasible_fraction_max": float(frac.max()) if len(frac) else math.nan}
    return out


def _scores(trials: pd.DataFrame, group: str) -> pd.DataFrame:
    g = trials[(trials["group"] == group) & trials["status"].eq("TERMINATED")]
    return g[[EPISODE_RETURN, EPISODE_COST, FEASIBLE, "cost_limit"]].apply(pd.to_numeric, errors="coerce")


def _figures(rows: pd.DataFrame) -> dict:
    ret = interval(rows[EPISODE_RETURN])
    cost = interval(rows[EPISODE_COST])
    limit = float(rows["cost_limit"].median()) if len(rows) else math.nan
    return {"n_seeds": int(len(rows)), "return": ret, "cost": cost,
            "p_feasible": float(rows[FEASIBLE].mean()) if len(rows) else math.nan,
            "feasible": bool(len(rows) and cost[0] <= limit), "limit": limit}


def rank(figures: dict) -> list[str]:
    """Algorithms ordered as the report ranks them: feasible on average first, then by mean return."""
    return sorted(figures, key=lambda a: (not figures[a]["feasible"], -_num(figures[a]["return"][0])))


def _num(x) -> float:
    return -math.inf if x is None or (isinstance(x, float) and math.isnan(x)) else x


def comparison(searched: dict, winners: dict, confirmation: pd.DataFrame) -> dict:
    """Per algorithm: its default and tuned figures on the fresh seeds, the gap and P(improvement),
    the winner's curse, its search's sensitivity; and both rankings."""
    per = {}
    for algo, tops in winners.items():
        tuned, default = _scores(confirmation, f"{algo}-{TUNED}1"), _scores(confirmation, f"{algo}-{DEFAULT}")
        t, d = _figures(tuned), _figures(default)
        per[algo] = {"tuned": t, "default": d, "winner": tops[0],
                     "gap": gap_interval(tuned[EPISODE_RETURN], default[EPISODE_RETURN]),
                     "p_improvement": probability_of_improvement(tuned[EPISODE_RETURN], default[EPISODE_RETURN]),
                     "curse": winners_curse(tops[0]["search"]["return_mean"], t["return"][0]),
                     "sensitivity": sensitivity(searched[algo][1])}
    tuned_rank = rank({a: v["tuned"] for a, v in per.items()})
    default_rank = rank({a: v["default"] for a, v in per.items()})
    return {"algorithms": per, "tuned_rank": tuned_rank, "default_rank": default_rank,
            "ranking_changed": tuned_rank != default_rank}


def _ci(t: tuple) -> str:
    point, lo, hi = t
    if point is None or (isinstance(point, float) and math.isnan(point)):
        return "–"
    return fmt_num(point) + ("" if math.isnan(lo) else f" [{fmt_num(lo)}, {fmt_num(hi)}]")


def markdown(tp, comp: dict) -> str:
    """The report as Markdown (the confirmation's parent run: tuned/report.md)."""
    t = tp.sweep.tune
    first = next(iter(tp.searches.values()))
    n, seeds, steps = first.sweep.num_samples, len(first.seeds), first.timesteps
    lines = [f"## Tuned comparison `{tp.name}` on `{tp.task}`", "",
             f"Every algorithm searched over its own space at the same budget: {n} {t.searcher.upper()} samples × "
             f"{seeds} seeds × {steps:,} env steps; each one's best and its default then rerun on "
             f"{t.confirm_seeds} fresh seeds (seeds {max(first.seeds) + 1}..{max(first.seeds) + t.confirm_seeds}). "
             "Return and cost: mean over seeds [95% bootstrap CI].", "",
             "| algorithm | default return | default cost | P(feas.) | tuned return | tuned cost | P(feas.) | "
             "gap tuned − default [CI] | P(improvement) | winner's curse |", "|---" * 10 + "|"]
    for algo, v in comp["algorithms"].items():
        d, tu = v["default"], v["tuned"]
        lines.append(f"| {algo} | {_ci(d['return'])} | {_ci(d['cost'])} | {fmt_num(d['p_feasible'])} | "
                     f"{_ci(tu['return'])} | {_ci(tu['cost'])} | {fmt_num(tu['p_feasible'])} | {_ci(v['gap'])} | "
                     f"{fmt_num(v['p_improvement'])} | {fmt_num(v['curse'])} |")
    lines += ["", "Winner's curse: the winner's mean return on the search's seeds minus on the fresh ones.", "",
              "| algorithm | tuned configuration | search return [CI] | configurations | return: best − median, IQR | "
              "cost: best − median, IQR | feasible configurations | seeds' feasible fraction |",
              "|---|---|---|---|---|---|---|---|"]
    for algo, v in comp["algorithms"].items():
        w, s = v["winner"], v["sensitivity"]
        fields = ", ".join(f"{k}={f'{x:.3g}' if isinstance(x, float) else x}" for k, x in w["fields"].items())
        search = (w["search"]["return_mean"], *(_nan(w["search"].get(k)) for k in ("return_mean_ci_low",
                                                                                     "return_mean_ci_high")))
        lines.append(f"| {algo} | {fields or '(its default)'}{'' if w['feasible'] else ' (none feasible: least cost)'}"
                     f" | {_ci(search)} | {s['configurations']} | {fmt_num(s['return_best_minus_median'])}, "
                     f"{fmt_num(s['return_iqr'])} | {fmt_num(s['cost_best_minus_median'])}, {fmt_num(s['cost_iqr'])} | "
                     f"{fmt_num(s['feasible_share'])} | {fmt_num(s['feasible_fraction_min'])}–"
                     f"{fmt_num(s['feasible_fraction_max'])} |")
    changed = "tuning changed it" if comp["ranking_changed"] else "tuning did not change it"
    lines += ["", f"**Ranking on the fresh seeds** (feasible on average first, then by return): tuned "
                  f"{' > '.join(comp['tuned_rank'])}; defaults {' > '.join(comp['default_rank'])}: {changed}.", ""]
    return "\n".join(lines)


def _nan(v) -> float:
    return math.nan if v is None else float(v)
