"""What a sweep ranks its trials by: the names a trial reports beside its row and the one scalar
Tune, ASHA and Optuna read. A module of its own, so that running (sweeps/trainable.py,
sweeps/sweep.py) and reading results (sweeps/reports/) import it and not each other.
"""

from __future__ import annotations

import math

INFEASIBLE_OFFSET = 1e6
#: What a trial reports beside its iteration's row: the score Tune, ASHA and Optuna rank by, the
#: constraint value Optuna's TPE reads (episode cost − limit, ≤ 0 feasible), the trial's wall time.
OBJECTIVE, CONSTRAINT, WALL_TIME_S = "objective", "constraint", "wall_time_s"


def objective(ret: float, cost: float, limit: float) -> float:
    """One scalar for Tune/ASHA/Optuna: feasible trials rank by return; every infeasible trial
    ranks below every feasible one (−10⁶ − violation), and less violation ranks higher."""
    if math.isnan(ret) or math.isnan(cost):
        return -2 * INFEASIBLE_OFFSET
    return ret if cost <= limit else -INFEASIBLE_OFFSET - (cost - limit)
