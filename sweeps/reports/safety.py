"""Safety statistics per configuration: how often its seeds end within the limit, and how much
cost above the limit its runs paid on the way there.

- ``p_feasible``: the fraction of its finished seeds whose final episode cost is within the limit
  (final episode_cost <= cost_limit), with the Wilson score interval. Why Wilson: with the 3-10
  seeds of a sweep the normal ("Wald") interval collapses to a point at 0/n and n/n and leaves
  [0, 1] otherwise; Wilson's keeps its coverage near the nominal 95% down to a few trials
  (Brown, Cai & DasGupta 2001) and has a closed form.
- ``violation``: over a run's logged iterations, the cost it spent above the limit, sum of
  max(0, episode_cost − cost_limit), a measure of how unsafe the *training* was, which the final
  cost does not show (docs/spec.md reports the final cost only). It depends on how many iterations
  a run logs, so ``violation_mean`` (per iteration) is given too; the worst iteration is where the
  excess over the limit peaked.

- training-time safety as Eckel et al. (2024) recommend reporting it: the ``cost_rate`` (the cost
  of every episode completed in training over the env steps sampled, each trial's last value;
  mean over seeds), the env steps to the first feasible iteration (``steps_to_feasible``: the mean
  over the seeds that got there, ``never_feasible`` how many did not) and the longest run of
  infeasible iterations (``longest_infeasible``, the most over its seeds).

Seeds are counted as sweeps.reports.report counts them: failed trials (status ERROR, or a NaN final return
or cost) and trials a scheduler stopped early (STOPPED) are left out, so ``n_seeds`` here equals
the summary's.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, COST_RATE, ENV_STEPS, EPISODE_COST
from sweeps.objective import feasible
from sweeps.reports.configurations import KEYS
from sweeps.reports.configurations import prepared as _prepared
from sweeps.reports.configurations import value_key as _value_key
from sweeps.reports.verdicts import proportion_interval

SAFETY_COLUMNS = ["n_seeds", "n_feasible", "p_feasible", "p_feasible_low", "p_feasible_high", "violation_total",
                  "violation_mean", "worst_excess", "worst_env_steps", "worst_trial_id", "final_cost_std",
                  "final_cost_min", "final_cost_max", "cost_rate", "steps_to_feasible", "never_feasible",
                  "longest_infeasible"]
VIOLATION_KEYS = ("violation_total", "violation_mean", "violating_iterations", "n_iterations", "worst_excess",
                  "worst_env_steps", "steps_to_feasible", "longest_infeasible")


def violation(curve: pd.DataFrame) -> dict:
    """Cost above the limit over a run's curve (env_steps, episode_cost, cost_limit), iterations
    with a NaN cost or limit left out; keys ``VIOLATION_KEYS``:

    violation_total = Σ max(0, episode_cost − cost_limit); violation_mean = that / n_iterations;
    violating_iterations = how many iterations were over the limit; worst_excess = the largest
    episode_cost − cost_limit (≤ 0 when the run never left the limit) and worst_env_steps where it
    happened (the first such iteration); steps_to_feasible = the env steps of the first iteration
    within the limit (NaN: none was); longest_infeasible = the most iterations in a row over it.
    All NaN when no iteration is usable."""
    empty = {k: math.nan for k in VIOLATION_KEYS} | {"n_iterations": 0, "violating_iterations": 0}
    if curve is None or not isinstance(curve, pd.DataFrame) or EPISODE_COST not in curve or COST_LIMIT not in curve:
        return empty
    cost = pd.to_numeric(curve[EPISODE_COST], errors="coerce").to_numpy(float)
    limit = pd.to_numeric(curve[COST_LIMIT], errors="coerce").to_numpy(float)
    steps = (pd.to_numeric(curve[ENV_STEPS], errors="coerce").to_numpy(float) if ENV_STEPS in curve
             else np.full(len(curve), np.nan))
    ok = np.isfinite(cost) & np.isfinite(limit)
    if not ok.any():
        return empty
    excess, steps = (cost - limit)[ok], steps[ok]
    total = float(np.clip(excess, 0, None).sum())
    worst = int(np.argmax(excess))
    within = np.flatnonzero(excess <= 0)
    return {"violation_total": total, "violation_mean": total / excess.size,
            "violating_iterations": int((excess > 0).sum()), "n_iterations": int(excess.size),
            "worst_excess": float(excess[worst]), "worst_env_steps": float(steps[worst]),
            "steps_to_feasible": float(steps[within[0]]) if within.size else math.nan,
            "longest_infeasible": longest_run(excess > 0)}


def longest_run(flags: np.ndarray) -> int:
    """The most ``True`` in a row in ``flags`` (0 when none)."""
    best = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        best = max(best, run)
    return best


def _with_limit(curve, limit: float):
    """The curve with its cost_limit filled from the trial's where the curve has none."""
    if not isinstance(curve, pd.DataFrame):
        return curve
    c = curve.copy()
    c[COST_LIMIT] = pd.to_numeric(c[COST_LIMIT], errors="coerce").fillna(limit) if COST_LIMIT in c else limit
    return c


def safety_table(trials: pd.DataFrame, curves: dict) -> pd.DataFrame:
    """One row per configuration (``KEYS``, in sweeps.reports.report.summarize's order) with
    ``SAFETY_COLUMNS``: n_seeds, n_feasible, p_feasible [p_feasible_low, p_feasible_high] (Wilson),
    the mean over its seeds of violation_total and violation_mean (seeds without a curve left out),
    the worst iteration over its seeds (worst_excess, worst_env_steps, worst_trial_id) and the
    spread of the final cost (final_cost_std with ddof=1, final_cost_min, final_cost_max)."""
    df, failed = _prepared(trials)
    scored = ~failed & ~df["status"].astype(str).eq("STOPPED")
    rows = []
    for key, g in df.groupby(KEYS, dropna=False, sort=False):
        ok = g[scored.loc[g.index]]
        final = pd.to_numeric(ok[EPISODE_COST], errors="coerce")
        limit = pd.to_numeric(ok[COST_LIMIT], errors="coerce")
        k = int(np.count_nonzero(feasible(final.to_numpy(float), limit.to_numpy(float))))  # NaN: not feasible
        p, lo, hi = proportion_interval(k, len(ok))
        runs = [(tid, violation(_with_limit(curves.get(tid), lim)))
                for tid, lim in zip(ok["trial_id"], limit) if tid in curves]
        runs = [(tid, v) for tid, v in runs if v["n_iterations"]]
        worst = max(runs, key=lambda tv: tv[1]["worst_excess"], default=(None, {}))
        reached = [v["steps_to_feasible"] for _, v in runs if not math.isnan(v["steps_to_feasible"])]
        rows.append(dict(
            zip(KEYS, key), n_seeds=len(ok), n_feasible=k, p_feasible=p, p_feasible_low=lo, p_feasible_high=hi,
            violation_total=float(np.mean([v["violation_total"] for _, v in runs])) if runs else math.nan,
            violation_mean=float(np.mean([v["violation_mean"] for _, v in runs])) if runs else math.nan,
            worst_excess=worst[1].get("worst_excess", math.nan),
            worst_env_steps=worst[1].get("worst_env_steps", math.nan), worst_trial_id=worst[0],
            final_cost_std=final.std(ddof=1), final_cost_min=final.min(), final_cost_max=final.max(),
            cost_rate=pd.to_numeric(ok[COST_RATE], errors="coerce").mean() if COST_RATE in ok else math.nan,
            steps_to_feasible=float(np.mean(reached)) if reached else math.nan,
            never_feasible=len(runs) - len(reached),
            longest_infeasible=max((v["longest_infeasible"] for _, v in runs), default=math.nan)))
    rows.sort(key=lambda r: (str(r["group"]), _value_key(r["value"]), str(r["task"]), r["param"]))
    return pd.DataFrame(rows, columns=KEYS + SAFETY_COLUMNS)
