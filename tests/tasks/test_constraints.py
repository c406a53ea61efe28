"""The constraints a task declares, the step costs read from them, and bad input refused in one line
before Ray starts (a config validates without Ray)."""

import math
import sys

import numpy as np
import pytest

from lac_rllib.algorithms import registry
from lac_rllib.tasks import get_task
from lac_rllib.tasks.constraints import Constraint, ConstraintSet
from lac_rllib.tasks.user import definition, register_definition, user_task


@pytest.mark.parametrize("task, names", [
    ("SafetyPointGoal1-v0", ("hazards",)),
    ("SafetyPointGoal2-v0", ("hazards", "vases")),
    ("SafetyCarButton1-v0", ("hazards", "gremlins", "buttons")),
    ("SafetyPointPush2-v0", ("hazards", "pillars")),
    ("SafetyPointCircle1-v0", ("boundary",)),
    ("SafetyPointGoal0-v0", ()),
    ("SafetyHopperVelocity-v1", ("velocity",)),
    ("lac/PointTwoCosts-v0", ("hazard", "lane")),
])
def test_each_task_declares_its_cost_sources(task, names):
    assert tuple(c.name for c in get_task(task).constraints) == names


@pytest.mark.parametrize("task", ["SafetyPointGoal2-v0", "SafetyPointButton1-v0"])
@pytest.mark.parametrize("backend", ["stock", "batched"])
def test_the_declared_keys_are_in_the_envs_info_and_their_indicator_is_info_cost(task, backend):
    """Every key a constraint names is in the env's step info, on both backends; and on every step
    info["cost"] (Safety-Gymnasium's indicator of any violation) is 1 exactly where some constraint's
    cost is 1: the constraints partition the summed cost's sources."""
    spec = get_task(task)
    env = spec.make({"env_backend": backend})
    env.reset(seed=0)
    env.action_space.seed(0)
    full = ConstraintSet(spec.constraints, (0.0,) * len(spec.constraints))
    seen = np.zeros(len(full))
    try:
        for step in range(1000):  # until some constraint cost (at least 200 steps)
            _, _, terminated, truncated, info = env.step(env.action_space.sample())
            costs = full.step_costs(info)  # raises naming a key the info lacks
            assert set(costs) <= {0.0, 1.0}
            assert info["cost"] == float(costs.max() > 0), (info, costs)
            seen += costs
            if terminated or truncated:
                env.reset()
            if step >= 200 and seen.sum() > 0:
                break
    finally:
        env.close()
    assert seen.sum() > 0, seen  # some constraint cost on this random walk: the comparison is not all zeros


def test_an_indicator_constraint_sums_its_keys_first():
    vases = Constraint("vases", ("cost_vases_contact", "cost_vases_velocity"), indicator=True)
    assert vases.step_cost({"cost_vases_contact": 1.0, "cost_vases_velocity": 1.0}) == 1.0
    assert vases.step_cost({"cost_vases_contact": 0.0, "cost_vases_velocity": 0.0}) == 0.0
    summed = Constraint("both", ("a", "b"))
    assert summed.step_cost({"a": 0.5, "b": 2.0}) == 2.5
    with pytest.raises(KeyError, match=r"constraint 'both'.*no 'b' \(keys: \['a'\]\)"):
        summed.step_cost({"a": 1.0})


def _build(algo="ppo_lag", task="SafetyPointGoal2-v0", **sets):
    return registry.build_config(algo, task, 0, sets, timesteps=10_000)


def test_limits_per_constraint_in_the_tasks_order():
    config = _build(constraints={"vases": 5, "hazards": 10})
    several = config.constraint_set
    assert several.names == ("hazards", "vases") and several.limits == (10.0, 5.0)
    assert config.num_constraints == 2 and config.effective_cost_limit == 15.0
    one = _build(constraints={"hazards": 7})
    assert one.num_constraints == 1 and one.effective_cost_limit == 7.0
    assert _build().constraint_set is None and _build().num_constraints == 1


@pytest.mark.parametrize("sets, message", [
    ({"constraints": {"pillars": 5}}, r"SafetyPointGoal2-v0 has no constraint 'pillars'; accepted: hazards, vases"),
    ({"constraints": {"hazards": -1}},
     r"constraints=\{'hazards': -1\} is invalid; accepted: None or a non-empty mapping"),
    ({"constraints": {"hazards": math.nan}}, r"constraints=\{'hazards': nan\} is invalid"),
    ({"constraints": {}}, r"constraints=\{\} is invalid"),
    ({"constraints": {"hazards": 5}, "cost_limit": 3.0}, r"cost_limit=3.0 and constraints=\{'hazards': 5\} together; "
                                                         r"accepted: one of them"),
])
def test_bad_constraints_are_refused_in_one_line(sets, message):
    with pytest.raises(ValueError, match=message) as err:
        _build(**sets)
    assert "\n" not in str(err.value)


def test_a_task_without_constraints_names_that():
    with pytest.raises(ValueError, match=r"has no constraint 'hazards'; accepted: none: it declares no constraints"):
        _build(task="lac/PointHazard-v0", constraints={"hazards": 1})


def test_a_users_env_declares_constraints_by_info_key(tmp_path, monkeypatch):
    (tmp_path / "two_cost_env.py").write_text(
        "from lac_rllib.tasks.point_hazard import PointTwoCostsEnv\n"
        "class NoSum(PointTwoCostsEnv):\n"
        "    def step(self, action):\n"
        "        obs, r, te, tr, info = super().step(action)\n"
        "        return obs, r, te, tr, {'near': info['cost_hazard'], 'up': info['cost_lane']}\n"
        "def make(config):\n    return NoSum()\n")
    monkeypatch.setattr(sys, "path", list(sys.path))
    spec = user_task("user/two-costs", factory="two_cost_env:make", cost_limit=5.0, preset="tiny",
                     constraints={"hazard": "near", "lane": "up"}, search_dirs=(str(tmp_path),))
    assert [(c.name, c.keys) for c in spec.constraints] == [("hazard", ("near",)), ("lane", ("up",))]
    assert register_definition(definition(spec)).constraints == spec.constraints  # travels as plain data
    env = spec.make()
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.0, 1.0], np.float32))  # up: into the upper half plane
    assert info["cost"] == info["near"] + info["up"] and info["up"] == 1.0  # no cost key: their sum
    with pytest.raises(ValueError, match=r"its step info has no 'speed', the key of constraint 'fast' "
                                         r"\(keys: \['near', 'up'\]\)"):
        user_task("user/two-costs-bad", factory="two_cost_env:make", cost_limit=5.0, preset="tiny",
                  constraints={"fast": "speed"}, search_dirs=(str(tmp_path),))


def test_an_algorithm_without_several_constraints_is_refused(monkeypatch):
    from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig

    monkeypatch.setattr(PPOLagConfig, "SEVERAL_CONSTRAINTS", False)
    with pytest.raises(ValueError, match=r"constraints hazards, vases: ppo_lag trains on one constraint only"):
        _build(constraints={"hazards": 10, "vases": 5})
