"""How a trial's multiplier behaved, read off its learning curve (one row per iteration: env steps,
the episode cost, the limit b, ν and ν's bound where it has one).

Spoor et al. ("Lagrangian methods in safe RL", 2026) judge a multiplier rule by its dynamics, not
its end point alone; per trial:

- ``steps_to_feasible``: env steps of the first iteration whose episode cost is ≤ b (NaN: never);
- ``overshoot``: after that first crossing, the deepest dip below the limit, max(b − cost) ≥ 0 (a
  multiplier that overshoots buys safety with return it did not need to give up);
- ``swing``: the cost's swings around b after the first crossing, the root mean square of
  cost − b over those iterations (0 when it settles on b);
- ``nu_at_zero`` / ``nu_at_bound``: the fraction of iterations with ν at 0, and with ν at its
  upper bound (NaN where the algorithm has none);
- ``cost_rate``: Σ cost / env steps over the whole training (the Safety Gym paper's headline), the
  run's own lifetime figure at its last iteration.

A fixed-multiplier trial (``nu_fixed``) gets the same figures: its ν never moves.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, COST_RATE, ENV_STEPS, EPISODE_COST, NU, NU_MAX
from sweeps.reports.safety import violation

#: The columns multiplier_behaviour returns, in the report's order.
BEHAVIOUR_COLUMNS = ["steps_to_feasible", "overshoot", "swing", "nu_at_zero", "nu_at_bound", "cost_rate"]
#: What a trial logs of them to its MLflow run (multiplier/steps_to_feasible, ...).
METRIC_PREFIX = "multiplier/"
#: ν counts as at 0, or at its bound, within this (ν is a float32 buffer).
AT = 1e-6


def _col(curve: pd.DataFrame, name: str) -> np.ndarray:
    if name not in curve:
        return np.full(len(curve), np.nan)
    return pd.to_numeric(curve[name], errors="coerce").to_numpy(dtype=float)


def multiplier_behaviour(curve: pd.DataFrame) -> dict[str, float]:
    """The module docstring's figures of one trial's ``curve`` (iterations in order; those without
    a cost or a limit are left out of the cost figures)."""
    curve = curve.sort_values(ENV_STEPS) if ENV_STEPS in curve else curve
    cost, limit = _col(curve, EPISODE_COST), _col(curve, COST_LIMIT)
    known = np.isfinite(cost) & np.isfinite(limit)
    out = dict.fromkeys(BEHAVIOUR_COLUMNS, math.nan)
    gap = (cost - limit)[known]
    out["steps_to_feasible"] = violation(curve)["steps_to_feasible"]  # safety's figure, one definition
    inside = np.flatnonzero(gap <= 0)
    if inside.size:
        after = gap[inside[0]:]
        out["overshoot"] = float(max(0.0, -after.min()))
        out["swing"] = float(np.sqrt(np.mean(after**2)))
    nu = _col(curve, NU)
    seen = np.isfinite(nu)
    if seen.any():
        out["nu_at_zero"] = float(np.mean(np.abs(nu[seen]) <= AT))
        bound = _col(curve, NU_MAX)[seen]
        if np.isfinite(bound).any():
            out["nu_at_bound"] = float(np.mean(np.isfinite(bound) & (nu[seen] >= bound - AT)))
    rate = _col(curve, COST_RATE)
    if np.isfinite(rate).any():
        out["cost_rate"] = float(rate[np.isfinite(rate)][-1])
    return out


def constraint_behaviour(curve: pd.DataFrame, limits: dict[str, float]) -> dict[str, float]:
    """With several constraints, :func:`multiplier_behaviour` of each constraint's own multiplier and
    cost against its limit (``nu/NAME``, ``episode_cost/NAME`` in the curve): ``FIGURE/NAME`` →
    value."""
    out = {}
    for name, b in limits.items():
        cost, nu = f"{EPISODE_COST}/{name}", f"{NU}/{name}"
        if cost not in curve:
            continue
        # the summed cost's rate and the largest ν's bound are not this constraint's: left out (NaN)
        own = curve.drop(columns=[c for c in (EPISODE_COST, NU, NU_MAX, COST_LIMIT, COST_RATE) if c in curve])
        own = own.rename(columns={cost: EPISODE_COST, nu: NU}).assign(**{COST_LIMIT: b})
        out.update({f"{k}/{name}": v for k, v in multiplier_behaviour(own).items()})
    return out


def behaviour_table(trials: pd.DataFrame, curves: dict, keys: list[str]) -> pd.DataFrame:
    """Per configuration (``keys``, the limit among them on a ladder), the mean over its seeds of each
    trial's figures (``curves``: trial id → curve), with how many seeds had a curve."""
    rows = []
    for key, g in trials.groupby(keys, dropna=False, sort=False):
        figures = [multiplier_behaviour(curves[t]) for t in g["trial_id"] if t in curves and len(curves[t])]
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,)), n_curves=len(figures))
        for col in BEHAVIOUR_COLUMNS:
            values = np.array([f[col] for f in figures], dtype=float)
            row[col] = float(np.nanmean(values)) if np.isfinite(values).any() else math.nan
        # Seeds that never reached the limit: their steps_to_feasible is NaN, so say how many did.
        row["n_reached"] = int(sum(math.isfinite(f["steps_to_feasible"]) for f in figures))
        rows.append(row)
    return pd.DataFrame(rows, columns=[*keys, "n_curves", "n_reached", *BEHAVIOUR_COLUMNS])
