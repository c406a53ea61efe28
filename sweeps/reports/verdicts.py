"""Verdicts: every interval a report prints, the one feasibility rule, ranking with ties, regret
against a frontier and the choice of winners. Every report calls this module; none computes an
interval or decides feasibility on its own.

**Feasibility** is the objective's rule, per seed (:func:`sweeps.objective.feasible`: a seed's final
cost ≤ its limit). A configuration is feasible when at least ``FEASIBLE_SHARE`` of its finished seeds
are (3 of 3, 4 of 5, 8 of 10): the summary's best feasible configuration, the ladder's rank, regret,
wins, the confirmation's and the registry's choice all read :func:`configuration_feasible`. A mean
cost under the limit is not feasibility: two seeds far over and one at 0 average under.

**Intervals**, each named by :data:`METHODS` in the reports, each with its coverage measured by a
seeded simulation in tests/sweeps/reports/test_verdicts.py (docs/sweeps.md, "Intervals", has the
figures):

- a mean: Student's t at level ``T_LEVEL`` (98%). A percentile bootstrap of 3 seeds returns their
  range (each all-min resample has probability 1/27 > 2.5%) and covers 76% of a normal mean; a 95%
  t-interval covers 95% on normal scores but 91-93% on skewed (lognormal σ = 0.5) ones at n = 3-10.
  At 98% it covers ≥ 95% of the mean on both: the level is raised so that what the report calls a
  95% interval covers at least 95% on the skewed scores a seed's return can have. On bimodal "some
  seeds fail" scores no interval over 3-5 seeds covers (the measured figures are in docs/sweeps.md);
- a difference of two configurations on different seeds (regret, a gap): Welch's t at ``T_LEVEL``;
- a paired difference (tuned − default on the same fresh seeds): t on the per-seed differences;
- a proportion (P(feasible)): Wilson's score interval at 95%.

**Ranking** (:func:`rank`): feasible configurations first, by mean return; then the others, by
their share of feasible seeds, then by mean violation. Rows whose return intervals overlap are
ties and share a rank: a row's rank is 1 + the number of rows clearly better than it (their
interval wholly above its own), so the report never orders what the seeds cannot.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pandas as pd
from scipy import stats

from sweeps.objective import feasible

CONFIDENCE = 0.95
"""The coverage every interval is read as (a 95% interval)."""
T_LEVEL = 0.98
"""The level of the t-intervals that cover ``CONFIDENCE`` on skewed scores (module docstring)."""
FEASIBLE_SHARE = 0.8
"""A configuration is feasible when at least this share of its finished seeds is."""
FEW_SEEDS = 5
"""Below this many seeds a report warns that rankings rest on few seeds."""

#: What each interval a report prints is, by column kind: the reports print these beside their tables.
METHODS = {
    "mean": f"Student-t at {T_LEVEL:.0%} (covers ≥ 95% of a mean on normal and lognormal scores, 3-10 seeds)",
    "difference": f"Welch's t at {T_LEVEL:.0%} on two independent sets of seeds",
    "paired": f"t at {T_LEVEL:.0%} on the per-seed differences (same seeds on both sides)",
    "proportion": "Wilson's score interval at 95%",
    "regret": (f"Welch's t at {T_LEVEL:.0%}: R*(b) on the frontier's held-out seeds (its ν chosen on the "
               "others) minus the configuration's return"),
}


def _finite(x) -> np.ndarray:
    a = np.asarray(x, dtype=float).ravel()
    return a[np.isfinite(a)]


@functools.lru_cache(maxsize=256)
def _t(df: float) -> float:
    return float(stats.t.ppf(0.5 + T_LEVEL / 2, df))


def mean_interval(scores) -> tuple[float, float, float]:
    """(mean, low, high) of the seeds' ``scores`` (NaN left out): Student's t at ``T_LEVEL``; NaN ends
    with one seed, the point itself when every seed scored the same."""
    x = _finite(scores)
    if not x.size:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if x.size < 2:
        return m, math.nan, math.nan
    half = _t(x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return m, m - half, m + half


def difference_interval(a, b) -> tuple[float, float, float]:
    """(mean(a) − mean(b), low, high) for seeds drawn apart: Welch's t at ``T_LEVEL`` (its
    Satterthwaite degrees of freedom); NaN ends with fewer than 2 seeds on a side."""
    x, y = _finite(a), _finite(b)
    if not x.size or not y.size:
        return math.nan, math.nan, math.nan
    d = float(x.mean() - y.mean())
    if x.size < 2 or y.size < 2:
        return d, math.nan, math.nan
    vx, vy = x.var(ddof=1) / x.size, y.var(ddof=1) / y.size
    se = math.sqrt(vx + vy)
    if se == 0:
        return d, d, d
    df = (vx + vy) ** 2 / (vx ** 2 / (x.size - 1) + vy ** 2 / (y.size - 1))
    half = _t(df) * se
    return d, d - half, d + half


def paired_difference_interval(a, b) -> tuple[float, float, float]:
    """(mean(a − b), low, high) for seeds paired by position (``a[i]`` and ``b[i]`` ran on the same
    seed): the t-interval of the differences; pairs with a NaN side are left out."""
    x, y = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if x.size != y.size:
        raise ValueError(f"paired scores need one per seed on each side; got {x.size} and {y.size}")
    return mean_interval(x - y)


def proportion_interval(k: int, n: int) -> tuple[float, float, float]:
    """(k/n, low, high): Wilson's score interval at ``CONFIDENCE``; the ends are exactly 0 at k = 0
    and 1 at k = n; all NaN when n = 0."""
    if n <= 0:
        return math.nan, math.nan, math.nan
    if not 0 <= k <= n:
        raise ValueError(f"k={k!r} must be in [0, n={n!r}]")
    p, z = k / n, float(stats.norm.ppf(0.5 + CONFIDENCE / 2))
    denom = 2 * (n + z * z)
    center = (2 * n * p + z * z) / denom
    delta = z / denom * math.sqrt(4 * n * p * (1 - p) + z * z)
    return p, (0.0 if k == 0 else center - delta), (1.0 if k == n else center + delta)


def probability_of_improvement(x, y, lower_is_better: bool = False) -> float:
    """P(a seed of X beats a seed of Y), ties one half (Mann-Whitney U / (n·m), as rliable computes
    it); NaN if either side is empty."""
    a, b = _finite(x), _finite(y)
    if not a.size or not b.size:
        return math.nan
    if lower_is_better:
        a, b = -a, -b
    return float(stats.mannwhitneyu(a, b, alternative="greater").statistic / (a.size * b.size))


def feasible_seeds(costs, limit) -> tuple[int, int]:
    """(feasible seeds, finished seeds) by the objective's per-seed rule (NaN costs left out)."""
    c = _finite(costs)
    return int(np.count_nonzero(feasible(c, limit))), int(c.size)


def configuration_feasible(costs, limit) -> bool:
    """The one verdict of a configuration's feasibility: at least ``FEASIBLE_SHARE`` of its finished
    seeds within ``limit`` (False without a finished seed or a limit)."""
    k, n = feasible_seeds(costs, limit)
    return bool(n) and not math.isnan(float(limit)) and k >= FEASIBLE_SHARE * n - 1e-12


def mean_violation(costs, limit) -> float:
    """Mean over seeds of max(0, cost − limit): how far over the limit an infeasible row is."""
    c = _finite(costs)
    return float(np.maximum(c - float(limit), 0).mean()) if c.size else math.nan


def verdict(returns, costs, limit) -> dict:
    """A configuration's figures at ``limit``: seeds, return and cost with their intervals, feasible
    seeds with P(feasible)'s interval, its mean violation and whether it is feasible."""
    ret, cost = np.asarray(returns, dtype=float), np.asarray(costs, dtype=float)
    ok = np.isfinite(ret) & np.isfinite(cost)
    k, n = feasible_seeds(cost[ok], limit)
    p = proportion_interval(k, n)
    return {"n_seeds": n, "n_feasible": k, "return": mean_interval(ret[ok]), "cost": mean_interval(cost[ok]),
            "p_feasible": p, "violation": mean_violation(cost[ok], limit),
            "feasible": configuration_feasible(cost[ok], limit)}


def rank(feasible_rows, return_mean, return_low, return_high, feasible_share, violation) -> np.ndarray:
    """1 = best, ties sharing a rank (module docstring). Each argument: one value per row. Rows
    without an interval (one seed) tie with no one unless their means are equal."""
    ok = np.asarray(feasible_rows, dtype=bool)
    m = np.asarray(return_mean, dtype=float)
    lo = np.where(np.isfinite(return_low), return_low, m).astype(float)
    hi = np.where(np.isfinite(return_high), return_high, m).astype(float)
    share, viol = np.asarray(feasible_share, dtype=float), np.asarray(violation, dtype=float)
    n_ok = int(ok.sum())
    out = np.zeros(len(ok), dtype=int)
    for i in range(len(ok)):
        if ok[i]:
            better = ok & (lo > hi[i]) & np.isfinite(lo) if np.isfinite(m[i]) else ok & np.isfinite(m)
            out[i] = 1 + int(better.sum())
        else:
            key = (np.nan_to_num(share, nan=-1.0), -np.nan_to_num(viol, nan=np.inf))
            mine = (key[0][i], key[1][i])
            better = ~ok & ((key[0] > mine[0]) | ((key[0] == mine[0]) & (key[1] > mine[1])))
            out[i] = n_ok + 1 + int(better.sum())
    return out


def rank_table(rows: pd.DataFrame) -> pd.Series:
    """:func:`rank` of a table with columns feasible, return_mean/_low/_high, n_feasible, n_seeds
    and violation (the ladder's, the tuned comparison's)."""
    share = rows["n_feasible"].astype(float) / rows["n_seeds"].replace(0, np.nan).astype(float)
    return pd.Series(rank(rows["feasible"], rows["return_mean"], rows["return_low"], rows["return_high"],
                          share, rows["violation"]), index=rows.index)


def ordered_with_ties(names, ranks) -> str:
    """``a > b = c > d``: the names by rank, '=' between ties."""
    pairs = sorted(zip(ranks, names), key=lambda p: p[0])
    out = ""
    for j, (r, name) in enumerate(pairs):
        out += name if j == 0 else (" = " if r == pairs[j - 1][0] else " > ") + name
    return out


def choose_winners(summary: pd.DataFrame, k: int, fields_of: dict | None = None, *,
                   least_costly_fallback: bool = False, default_competes: bool = False) -> pd.DataFrame:
    """The ``k`` configurations a confirmation reruns, best first: the rows of ``summary`` (one per
    configuration: config, group, feasible, return_mean, return_mean_ci_low, cost_mean, n_seeds,
    is_default) feasible by this module's rule, by the lower end of their return interval, then
    their mean (one seed has no interval). The frontier's fixed-ν runs are the yardstick, never a
    candidate; nor is the default, rerun beside the winners, unless ``default_competes``. With
    ``fields_of`` (config → its fields' values) a configuration ranked at several limits of a ladder
    is one winner, its best row. Where none is feasible: no row, or with ``least_costly_fallback``
    the least costly configurations with a finished seed (then the higher return), their
    ``feasible`` False: a row is a feasible winner only where the rule says so."""
    import json

    from sweeps.spaces import FRONTIER_GROUP

    if summary.empty:  # a sweep that finished no trial
        return summary
    candidates = summary[~summary["group"].astype(str).eq(FRONTIER_GROUP)]
    if not default_competes:
        candidates = candidates[~candidates["is_default"].astype(bool)]
    ok = candidates[candidates["feasible"].astype(bool) & candidates["return_mean"].notna()]
    if len(ok):
        order = (ok.assign(_low=ok["return_mean_ci_low"].fillna(-math.inf))
                 .sort_values(["_low", "return_mean"], ascending=False).drop(columns="_low"))
    elif least_costly_fallback:
        done = candidates[pd.to_numeric(candidates["n_seeds"], errors="coerce").fillna(0) > 0]
        order = done.sort_values(["cost_mean", "return_mean"], ascending=[True, False])
    else:
        return ok
    if fields_of is None:
        return order.head(k)
    seen, keep = set(), []
    for i, config in enumerate(order["config"]):
        key = json.dumps(fields_of[config], sort_keys=True, default=str) if fields_of.get(config) else config
        if key not in seen:
            seen.add(key)
            keep.append(i)
        if len(keep) == k:
            break
    return order.iloc[keep]


# -- the frontier and regret ---------------------------------------------------------------------

def split_seeds(seeds) -> tuple[list, list]:
    """The frontier's seeds split in two: ν is chosen on the first half (the smaller when odd) and
    R*(b) measured on the rest, so the choice of the best ν does not flatter R*'s estimate (a
    maximum over noisy points measured on the seeds it was chosen on is biased upward)."""
    s = sorted(set(seeds))
    return s[:len(s) // 2], s[len(s) // 2:]


MIN_FRONTIER_SEEDS = 3
"""Seeds per fixed ν the frontier needs: one to choose ν on, two to measure R*(b) on."""


def best_within(points: pd.DataFrame, limit: float) -> dict:
    """R*(b) from the frontier's per-seed scores (``points``: nu, seed, return, cost): among the ν
    feasible by the rule on the choosing seeds, the one of the best mean return there; R*(b) is its
    mean return on the held-out seeds, ``r_star_scores`` those seeds' returns, provided the rule holds
    on those seeds too. ``why`` says in one line why there is no R*(b) (too few seeds, no feasible
    point, the chosen ν infeasible on its held-out seeds)."""
    none = {"r_star": math.nan, "r_star_nu": "", "r_star_scores": np.array([]), "why": ""}
    if points.empty:
        return none | {"why": "no frontier ran"}
    choose_on, measure_on = split_seeds(points["seed"])
    if not choose_on:
        return none | {"why": f"the frontier has {len(measure_on)} seed(s) per ν; it needs ≥ {MIN_FRONTIER_SEEDS}"}
    # numpy, not a groupby: the coverage simulation calls this tens of thousands of times.
    nus, seed = points["nu"].to_numpy(), points["seed"].to_numpy()
    ret, cost = points["return"].to_numpy(dtype=float), points["cost"].to_numpy(dtype=float)
    choosing, measuring = np.isin(seed, choose_on), np.isin(seed, measure_on)
    best, best_mean = None, -math.inf
    for nu in pd.unique(nus):
        m = choosing & (nus == nu)
        r = ret[m][np.isfinite(ret[m])]
        if m.any() and r.size and configuration_feasible(cost[m], limit) and r.mean() > best_mean:
            best, best_mean = nu, float(r.mean())
    if best is None:
        return none | {"why": f"no fixed ν is feasible within b = {limit:g} on the frontier's choosing seeds"}
    measured = measuring & (nus == best)
    held = ret[measured]
    if held.size and not configuration_feasible(cost[measured], limit):
        # The one rule on the seeds that measure R*(b) too: a return the chosen ν does not reach
        # within b on fresh seeds is no feasible reference for a regret.
        k, n = feasible_seeds(cost[measured], limit)
        return none | {"r_star_nu": best, "why": f"ν = {best}, chosen on half the seeds, fails the rule on the "
                                                  f"held-out ones ({k} of {n} within b = {limit:g})"}
    return {"r_star": float(np.mean(held)) if held.size else math.nan, "r_star_nu": best, "r_star_scores": held,
            "why": "" if held.size else "the chosen ν has no held-out seed"}


def regret(star: dict, returns, is_feasible: bool) -> tuple[float, float, float]:
    """(R*(b) − R, low, high) with :data:`METHODS` ``regret``; NaN where the row is not feasible (its
    violation is what the report gives instead) or there is no R*(b)."""
    if not is_feasible or not np.isfinite(star["r_star"]):
        return math.nan, math.nan, math.nan
    return difference_interval(star["r_star_scores"], returns)


# -- a summary's statistics columns ---------------------------------------------------------------

def iqm(scores) -> float:
    """The interquartile mean (rliable's IQM: the mean of the middle 50%), a point without an
    interval: no interval of it over 3-10 seeds has a measured coverage here."""
    x = _finite(scores)
    return float(stats.trim_mean(x, 0.25)) if x.size else math.nan


#: The summary's statistics columns (return_mean and cost_mean are the summary's own).
STAT_COLUMNS = [*(f"{m}_mean_ci_{end}" for m in ("return", "cost") for end in ("low", "high")),
                "return_iqm", "cost_iqm", "poi_return_vs_default", "poi_cost_vs_default"]


def seed_statistics(returns, costs, default_returns=None, default_costs=None) -> dict:
    """A configuration's :data:`STAT_COLUMNS`: its mean's interval and IQM for return and cost, and
    P(improvement) over the default's seeds (for cost, a lower cost is the improvement)."""
    out = {}
    for name, scores in (("return", returns), ("cost", costs)):
        _, out[f"{name}_mean_ci_low"], out[f"{name}_mean_ci_high"] = mean_interval(scores)
        out[f"{name}_iqm"] = iqm(scores)
    has_default = default_returns is not None and len(default_returns)
    out["poi_return_vs_default"] = probability_of_improvement(returns, default_returns) if has_default else math.nan
    out["poi_cost_vs_default"] = (probability_of_improvement(costs, default_costs, lower_is_better=True)
                                  if has_default else math.nan)
    return out


def seeds_line(n_seeds: list[int]) -> str:
    """How many seeds the intervals rest on and what they are, with a warning under ``FEW_SEEDS``."""
    if not n_seeds:
        return "No finished seeds: no statistics."
    lo, hi = min(n_seeds), max(n_seeds)
    count = f"{lo}" if lo == hi else f"{lo}-{hi}"
    line = (f"Intervals of a mean: {METHODS['mean']}, over {count} seeds per configuration; P(feasible): "
            f"{METHODS['proportion']}.")
    if lo < FEW_SEEDS:
        line += (f" **Warning: fewer than {FEW_SEEDS} seeds per configuration: rankings between configurations "
                 "whose intervals overlap are ties, and single failing seeds are not covered; run more seeds "
                 "(--seeds).**")
    return line
