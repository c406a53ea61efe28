"""The summary's table per constraint (sweeps/reports/constraints.py)."""

import math

import pandas as pd
import pytest

from sweeps.reports.constraints import constraints_markdown, constraints_table
from sweeps.reports.verdicts import mean_interval, proportion_interval


def _trials():
    rows = []
    # apart: hazard (limit 2) within on every seed, lane (limit 10) broken on seed 2: joint 2/3.
    for seed, (h, la) in enumerate([(0.0, 8.0), (1.0, 9.0), (1.5, 12.0)]):
        rows.append({"group": "g", "param": "", "value": None, "task": "t", "config": "apart", "seed": seed,
                     "status": "TERMINATED", "episode_cost/hazard": h, "episode_cost/lane": la,
                     "cost_limit/hazard": 2.0, "cost_limit/lane": 10.0, "episode_cost": max(h - 2.0, la - 10.0)})
    rows.append({**rows[-1], "seed": 3, "status": "ERROR", "episode_cost/lane": 99.0, "episode_cost": 89.0})
    return pd.DataFrame(rows)


def test_each_constraint_and_the_joint_rule_with_their_intervals():
    table = constraints_table(_trials()).set_index("constraint")
    lane, hazard, joint = table.loc["lane"], table.loc["hazard"], table.loc["joint"]
    assert (hazard["feasible_seeds"], hazard["seeds"]) == (3, 3)
    assert (lane["feasible_seeds"], lane["seeds"]) == (2, 3)  # the failed trial is left out
    assert (joint["feasible_seeds"], joint["seeds"]) == (2, 3)
    assert (lane["cost_mean"], lane["cost_low"], lane["cost_high"]) == pytest.approx(mean_interval([8.0, 9.0, 12.0]))
    assert (joint["p_feasible"], joint["p_feasible_low"], joint["p_feasible_high"]) == pytest.approx(
        proportion_interval(2, 3))
    assert math.isnan(joint["cost_limit"])
    text = constraints_markdown(_trials())
    assert "| apart | t | lane | 9.67 [" in text and "| 10 | 2/3 |" in text
    assert "| apart | t | joint | – | – | 2/3 |" in text


def test_nothing_without_several_constraints():
    one = pd.DataFrame({"group": ["g"], "param": [""], "value": [None], "task": ["t"], "config": ["c"],
                        "episode_cost": [1.0], "cost_limit": [25.0]})
    assert constraints_table(one).empty and constraints_markdown(one) == ""
