"""sweeps/reports/multiplier.py: a multiplier's behaviour from a hand-made cost and ν trace."""

import math

import pandas as pd

from sweeps.reports.multiplier import multiplier_behaviour

# b = 10; cost over the limit twice, first within at 3000 steps, then 4 below, 3 above, 0 off it.
TRACE = pd.DataFrame({"env_steps": [1000, 2000, 3000, 4000, 5000, 6000],
                      "episode_cost": [20.0, 15.0, 8.0, 6.0, 13.0, 10.0], "cost_limit": [10.0] * 6,
                      "nu": [0.0, 0.0, 0.5, 1.0, 0.8, 2.0], "nu_max": [2.0] * 6,
                      "cost_rate": [0.02, 0.0175, 0.0143, 0.0123, 0.0125, 0.012]})


def test_the_figures_of_a_hand_made_trace():
    b = multiplier_behaviour(TRACE)
    assert b["steps_to_feasible"] == 3000  # the first iteration with cost ≤ 10
    assert b["overshoot"] == 4.0  # after it: gaps −2, −4, 3, 0; the deepest dip is 4 below
    assert math.isclose(b["swing"], math.sqrt((4 + 16 + 9 + 0) / 4))  # RMS of those gaps
    assert b["nu_at_zero"] == 2 / 6 and b["nu_at_bound"] == 1 / 6  # ν = 0 twice, at its bound 2 once
    assert b["cost_rate"] == 0.012  # the run's lifetime rate at its last iteration


def test_a_run_that_never_reaches_the_limit_and_has_no_bound():
    never = TRACE.assign(episode_cost=[20.0] * 6).drop(columns="nu_max")
    b = multiplier_behaviour(never)
    assert all(math.isnan(b[k]) for k in ("steps_to_feasible", "overshoot", "swing", "nu_at_bound"))
    assert b["nu_at_zero"] == 2 / 6
