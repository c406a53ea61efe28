"""Chain-health flags per configuration: is LAC's Langevin chain doing what the paper intends, or
is it pinned at the action bounds, throttled by the gradient clip, or fed by a collapsed actor?

Read from each trial's final-iteration learner metrics (lac_rllib/constrained/metrics.py, "Chain
health"), averaged over the configuration's seeds:

- ``langevin_at_bound`` > AT_BOUND_MAX: "end points on the bound (x%)". The chain is clamped to
  the action box ([C], lac_rllib/algorithms/lac/langevin.py), so an end point on the bound is an
  action the energy pushed past it. The defaults end at 2-11% on PointGoal1, the unclipped old
  defaults at 8-19% (docs/fidelity, final iterations); on the tiny task the unclipped chain ends
  at 49% and still learns. A flag is a reason to look, not a verdict.
- ``langevin_clip_fraction`` >= CLIP_EVERY_STEP: "clip binds every step": every chain step was
  shortened by the clip, so the step length is set by the clip, not by the energy's gradient.
  The clipped defaults do this on PointGoal1 (docs/fidelity: 1.0): read it as "the clip, not η,
  sets the step", a fact to know when tuning η, not as a failure.
- ``actor_std_mean`` < STD_COLLAPSED: "σ collapsed (σ=...)". LAC's actor has one free,
  state-independent log σ with no lower clamp (networks.GaussianActor, log_std_init −0.5:
  σ ≈ 0.61), so nothing stops σ shrinking. Healthy runs end at σ ≈ 0.17-0.35 on actions in
  [−1, 1] (docs/fidelity); 0.05 is 2.5% of that range, where the chain's informative start
  ã_0 ~ π_φ' is a near point and exploration comes from the chain's noise alone.

A configuration without these metrics (a baseline: PPO-Lag, SAC-Lag), or with NaN, gets "".
"""

from __future__ import annotations

import pandas as pd

from lac_rllib.constrained.metrics import ACTOR_STD_MEAN, LANGEVIN_AT_BOUND, LANGEVIN_CLIP_FRACTION
from sweeps.reports.configurations import KEYS, text_column

AT_BOUND_MAX = 0.10  # mean fraction of chain end points on an action bound above which it is flagged
CLIP_EVERY_STEP = 0.99  # mean clip fraction from which "the clip binds every step"
STD_COLLAPSED = 0.05  # mean actor σ below which it is flagged (actions in [-1, 1]; see the docstring)
HEALTH_COLUMNS = (LANGEVIN_AT_BOUND, LANGEVIN_CLIP_FRACTION, ACTOR_STD_MEAN)
SEPARATOR = "; "


def flags_of(at_bound: float, clip_fraction: float, std: float) -> str:
    """The flags of one configuration's mean chain metrics ("" when healthy or unknown); a NaN
    metric raises no flag."""
    out = []
    if at_bound > AT_BOUND_MAX:  # NaN compares False
        out.append(f"end points on the bound ({at_bound:.0%})")
    if clip_fraction >= CLIP_EVERY_STEP:
        out.append("clip binds every step")
    if std < STD_COLLAPSED:
        out.append(f"σ collapsed (σ={std:.3g})")
    return SEPARATOR.join(out)


def chain_flags(final_metrics: pd.DataFrame) -> pd.Series:
    """Flags per configuration: a str Series named "chain_flags" indexed by ``KEYS`` (a MultiIndex,
    the configurations in order of appearance); each metric is the mean over the configuration's
    trials that have it. A missing metric column counts as NaN."""
    df = final_metrics.copy()
    df["param"] = text_column(df, "param")
    df["config"] = text_column(df, "config")
    for col in HEALTH_COLUMNS:
        df[col] = pd.to_numeric(df[col], errors="coerce") if col in df else float("nan")
    means = df.groupby(KEYS, dropna=False, sort=False)[list(HEALTH_COLUMNS)].mean()
    flags = [flags_of(*(float(r[c]) for c in HEALTH_COLUMNS)) for _, r in means.iterrows()]
    return pd.Series(flags, index=means.index, name="chain_flags", dtype=object)
