"""What a sweep ranks a trial on: the mean over the final 10% of its iterations, not the last one.

The last iteration's episode return and cost are the mean over the few episodes the stochastic
policy completed in one iteration: one noisy sample of an exploring policy (issue 36; Eimer et al.
2023, Hamilton et al. 2022 on single final samples). The score is the mean over the iterations in
the final ``TAIL`` of the trial's env steps (those past (1 − TAIL) × its last env steps), as
``docs/fidelity/`` scores runs (benchmarks/fidelity.py), at least the last iteration. The sweep's
reports, its objective and feasibility, the frontier, the importances, the table and what Optuna is
told all read it; the last iteration's values stay beside it (``last_return``, ``last_cost``).
"""

from __future__ import annotations

import math

import pandas as pd

from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN

#: The fraction of a trial's env steps, at its end, whose iterations its score averages.
TAIL = 0.10
#: The final-iteration values a trial keeps beside its score (trials.csv, summary).
LAST_RETURN, LAST_COST = "last_return", "last_cost"
#: What a finished trial logs and reports as its score (MLflow metrics, Tune's last result).
SCORE_RETURN, SCORE_COST = "score_return", "score_cost"
#: How the reports say what they rank on.
DESCRIPTION = (f"each trial's score is the mean of its episode return and cost over the iterations in its final "
               f"{TAIL:.0%} of env steps (the last iteration's alone: `{LAST_RETURN}`, `{LAST_COST}` in trials.csv)")


def train_score(curve: pd.DataFrame | None) -> tuple[float, float]:
    """(return, cost) of a learning curve (env_steps, episode_return, episode_cost per iteration):
    their means over the iterations past (1 − TAIL) × the last env steps; NaN without iterations."""
    if curve is None or not len(curve) or ENV_STEPS not in curve:
        return math.nan, math.nan
    steps = pd.to_numeric(curve[ENV_STEPS], errors="coerce")
    tail = curve[steps > (1 - TAIL) * steps.max()]
    if tail.empty:  # one iteration, or steps unknown: the last iteration
        tail = curve.tail(1)
    return (float(pd.to_numeric(tail[EPISODE_RETURN], errors="coerce").mean()),
            float(pd.to_numeric(tail[EPISODE_COST], errors="coerce").mean()))
