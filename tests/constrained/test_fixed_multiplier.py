"""``nu_fixed``: every algorithm with a Lagrange multiplier can hold ν at a value for a whole run (the
fixed-multiplier frontier's runs); the algorithms without one do not have the field."""

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID

from lac_rllib.algorithms import registry
from lac_rllib.constrained.lagrange import HeldStep, LagrangeMultiplier, fixed_multiplier
from lac_rllib.constrained.metrics import NU, iteration_row

TASK = "lac/PointHazard-v0"
LAGRANGIAN = [a for a in registry.ALGOS if registry.has_multiplier(a)]


def test_the_lagrangian_algorithms_have_the_field_and_the_others_refuse_it():
    assert set(LAGRANGIAN) == {"lac", "ppo_lag", "sac_lag", "focops", "cup", "respo", "trpo_lag"}
    for algo in ("p3o", "cpo", "pcpo"):
        with pytest.raises(ValueError, match="nu_fixed"):
            registry.parse_sets(algo, ["nu_fixed=0.5"])


def test_a_held_multiplier_neither_steps_nor_is_bounded():
    nu = torch.tensor(0.0)
    config = type("C", (), {"nu_fixed": 3.0, "effective_cost_limit": 0.0})()
    held = fixed_multiplier(nu.fill_(3.0), config)
    assert isinstance(held, LagrangeMultiplier) and isinstance(held.rule, HeldStep) and held.upper is None
    assert [held.step(c) for c in (100.0, 0.0, 1e9)] == [3.0, 3.0, 3.0]
    assert fixed_multiplier(nu, type("C", (), {"nu_fixed": None})()) is None


@pytest.mark.parametrize("algo", LAGRANGIAN)
def test_nu_stays_at_its_fixed_value_where_a_learning_one_would_move(ray_session, algo):
    """At limit 0 on a task that costs, a learning ν rises (checked on the same run with ν free);
    held at 0.7 it reads 0.7 after every iteration, in the module and in the row."""
    base = {**registry.budget_fields(algo, "smoke", "tiny"), "cost_limit": 0.0}
    nus = {}
    for name, sets in (("held", {**base, "nu_fixed": 0.7}), ("free", base)):
        algo_obj = registry.build_config(algo, TASK, 0, sets, timesteps=10_000).build_algo()
        try:
            rows = [iteration_row(algo_obj.train()) for _ in range(3)]
            nus[name] = ([r[NU] for r in rows],
                         float(algo_obj.learner_group._learner.module[DEFAULT_MODULE_ID].nu))
        finally:
            algo_obj.stop()
    assert nus["held"][0] == pytest.approx([0.7] * 3) and nus["held"][1] == pytest.approx(0.7)
    assert nus["free"][1] != pytest.approx(0.7)  # the field, not the task, held it
