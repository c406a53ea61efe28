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
#: The objective of the means of a PBT member's last iterations (sweeps/pbt.py ranks members on it).
OBJECTIVE_WINDOW = "objective_window"


def feasible(cost, limit):
    """The one feasibility rule, per seed: a run is feasible when its final episode cost is within its
    limit (cost ≤ limit; a NaN on either side is not). Scalars or numpy arrays alike; every verdict of
    the reports reads it through sweeps/reports/verdicts.py."""
    import numpy as np

    with np.errstate(invalid="ignore"):
        out = np.less_equal(cost, limit)
    return bool(out) if np.ndim(out) == 0 else out


def objective(ret: float, cost: float, limit: float) -> float:
    """One scalar for Tune/ASHA/Optuna: feasible trials rank by return; every infeasible trial
    ranks below every feasible one (−10⁶ − violation), and less violation ranks higher."""
    if math.isnan(ret) or math.isnan(cost):
        return -2 * INFEASIBLE_OFFSET
    return ret if feasible(cost, limit) else -INFEASIBLE_OFFSET - (cost - limit)
