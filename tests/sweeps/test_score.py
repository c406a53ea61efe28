"""The score a sweep ranks a trial on (sweeps/score.py): its final 10% of iterations, not the last."""

import math

import pandas as pd
import pytest

from sweeps import score
from sweeps.results import scored


def _curve(costs, returns=None, step=1000):
    returns = returns or [1.0] * len(costs)
    return pd.DataFrame({"env_steps": [step * (i + 1) for i in range(len(costs))], "episode_return": returns,
                         "episode_cost": costs, "cost_limit": 25.0})


def test_the_score_is_the_mean_over_the_final_tenth_of_the_env_steps():
    # 20 iterations of 1000 steps: the final 10% are the iterations past 18,000 steps: the last two.
    costs = [40.0] * 18 + [20.0, 30.0]
    ret, cost = score.train_score(_curve(costs, returns=list(range(20))))
    assert (ret, cost) == (pytest.approx(18.5), pytest.approx(25.0))
    assert score.train_score(_curve([7.0], returns=[3.0])) == (3.0, 7.0)  # one iteration: itself
    assert all(math.isnan(x) for x in score.train_score(None))


def test_a_trial_whose_last_iteration_is_infeasible_ranks_as_its_final_tenth_says():
    """Its last iteration is over the limit (30 > 25), its final 10% within (mean 24): feasible,
    with the objective of its score; the last values are kept beside it."""
    row = {"episode_return": 9.0, "episode_cost": 30.0, "cost_limit": 25.0, "feasible": 0.0, "objective": -1e6 - 5}
    curve = _curve([40.0] * 18 + [18.0, 30.0], returns=[1.0] * 18 + [11.0, 9.0])
    out = scored(row, curve)
    assert (out["episode_return"], out["episode_cost"], out["feasible"]) == (10.0, 24.0, 1.0)
    assert out["objective"] == 10.0 and (out["last_return"], out["last_cost"]) == (9.0, 30.0)
    # And the other way round: a last iteration within the limit after a final 10% over it.
    worse = scored({**row, "episode_cost": 20.0, "feasible": 1.0, "objective": 9.0},
                   _curve([0.0] * 18 + [40.0, 20.0]))
    assert worse["feasible"] == 0.0 and worse["objective"] == pytest.approx(-1e6 - 5.0)
    # No curve: the last values stand.
    assert scored(row, None)["episode_cost"] == 30.0
