"""Statistics over seeds for a sweep's report: rliable's measures (Agarwal et al., NeurIPS 2021)
computed with scipy.

Per configuration, the final return and the final cost of its seeds are summarised by their mean
and their interquartile mean (IQM: the mean of the middle 50%, robust to one outlying seed), each
with a 95% percentile-bootstrap confidence interval over the seeds (rliable's stratified bootstrap
with one task per configuration is exactly this), and compared with the default configuration by
the probability of improvement P(X > Y) (the Mann-Whitney U statistic over all seed pairs, ties
counting one half, as rliable computes it). For cost, "improvement" is a lower cost.

Why not rliable itself: it requires ``arch < 8``, and arch 7.x fails at import under pandas 3
(which numpy 2 needs here); docs/dependencies.md, "Statistics".

Intervals need at least 2 seeds and mean little under 5 (Colas et al. 2018; Agarwal et al. 2021):
the report says how many seeds they rest on and warns below ``FEW_SEEDS``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

CONFIDENCE = 0.95
REPS = 2000  # bootstrap resamples: the CI's ends move by < 1% of its width beyond this here
SEED = 0  # the bootstrap's resampling is seeded: the same sweep gives the same report
FEW_SEEDS = 5
STAT_COLUMNS = [f"{m}_{a}{end}" for m in ("return", "cost") for a in ("mean", "iqm")
                for end in ("", "_ci_low", "_ci_high") if (a, end) != ("mean", "")] + [
    "poi_return_vs_default", "poi_cost_vs_default"]  # return_mean/cost_mean are the summary's own
# Each takes an ``axis`` so that the bootstrap evaluates all resamples in one vectorized call.
AGGREGATES = {"mean": lambda x, axis=None: np.mean(x, axis=axis),
              "iqm": lambda x, axis=None: stats.trim_mean(x, 0.25, axis=axis)}


def interval(scores, aggregate: str = "mean") -> tuple[float, float, float]:
    """(point estimate, CI low, CI high) of ``aggregate`` over the seeds' ``scores``; the interval
    is NaN with fewer than 2 seeds (a bootstrap of one value says nothing)."""
    x = np.asarray(scores, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    func = AGGREGATES[aggregate]
    point = float(func(x))
    if x.size < 2 or np.all(x == x[0]):  # no spread: the interval is the point
        return (point, math.nan, math.nan) if x.size < 2 else (point, point, point)
    res = stats.bootstrap((x,), func, n_resamples=REPS,
                          confidence_level=CONFIDENCE, method="percentile", vectorized=True,
                          rng=np.random.default_rng(SEED))
    return point, float(res.confidence_interval.low), float(res.confidence_interval.high)


def probability_of_improvement(x, y, lower_is_better: bool = False) -> float:
    """P(a seed of X beats a seed of Y), ties one half (U / (n·m)); NaN if either side is empty."""
    a, b = (np.asarray(v, dtype=float) for v in (x, y))
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if a.size == 0 or b.size == 0:
        return math.nan
    if lower_is_better:
        a, b = -a, -b
    return float(stats.mannwhitneyu(a, b, alternative="greater").statistic / (a.size * b.size))


def seed_statistics(returns, costs, default_returns=None, default_costs=None) -> dict:
    """The statistics columns of one configuration (see the module docstring)."""
    out = {}
    for name, scores in (("return", returns), ("cost", costs)):
        for agg in AGGREGATES:
            point, lo, hi = interval(scores, agg)
            if agg != "mean":  # the mean itself is the summary's return_mean / cost_mean
                out[f"{name}_{agg}"] = point
            out[f"{name}_{agg}_ci_low"], out[f"{name}_{agg}_ci_high"] = lo, hi
    has_default = default_returns is not None and len(default_returns)
    out["poi_return_vs_default"] = (probability_of_improvement(returns, default_returns) if has_default
                                    else math.nan)
    out["poi_cost_vs_default"] = (probability_of_improvement(costs, default_costs, lower_is_better=True)
                                  if has_default else math.nan)
    return out


def seeds_line(n_seeds: list[int]) -> str:
    """How many seeds the intervals rest on, with a warning under ``FEW_SEEDS``."""
    if not n_seeds:
        return "No finished seeds: no statistics."
    lo, hi = min(n_seeds), max(n_seeds)
    count = f"{lo}" if lo == hi else f"{lo}-{hi}"
    line = (f"Intervals: {CONFIDENCE:.0%} percentile-bootstrap confidence intervals ({REPS} resamples) over "
            f"{count} seeds per configuration.")
    if lo < FEW_SEEDS:
        line += (f" **Warning: fewer than {FEW_SEEDS} seeds per configuration: the intervals are wide and "
                 "rankings between configurations may not hold up; run more seeds (--seeds).**")
    return line
