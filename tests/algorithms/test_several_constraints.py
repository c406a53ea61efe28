"""Several constraints at once, for every algorithm, on ``lac/PointTwoCosts-v0`` (the tiny task with
two costs, hazard and lane): the lane's limit binds (the first policies pay ~95 an episode above
the x axis, its limit 10) and the hazard's is slack (1000: never reached). Each algorithm's
multiplier for the lane (CPO's and PCPO's dual variable ν*, P3O's penalty weight) rises, the lane's
cost comes under its limit (the mean of the last 3 iterations), and the hazard's multiplier stays
at 0: each constraint is held by its own multiplier. Seed 0, 10 iterations of the tiny preset
(5-12 s each here)."""

import numpy as np
import pytest

from lac_rllib.algorithms import registry
from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, FEASIBLE, NU, iteration_row, per_constraint

TASK = "lac/PointTwoCosts-v0"
LIMITS = {"hazard": 1000.0, "lane": 10.0}
TAIL, ITERATIONS = 3, 10
#: Fields set beside: RESPO's ν₀ is softplus(0.25) and its rate 5e-5 [G], so its ν starts at 0 and
#: steps as PPO-Lag's can; SAC-Lag's λ steps after 2 iterations (not 5) and it makes a quarter of its
#: gradient steps (the test's time).
SETS = {"respo": {"nu_init": 0.0, "nu_parametrization": "direct", "lagrangian_lr": 0.05},
        "sac_lag": {"warmup_env_steps": 2000, "updates_per_env_step": 0.25}}


@pytest.mark.slow
@pytest.mark.parametrize("algo", list(registry.ALGOS))
def test_the_binding_constraint_is_held_and_the_slack_one_left_alone(ray_session, algo):
    config = registry.build_config(algo, TASK, 0, {"constraints": LIMITS, **SETS.get(algo, {})}, timesteps=100_000)
    assert config.num_constraints == 2
    algo_obj = config.build_algo()
    try:
        rows = [iteration_row(algo_obj.train()) for _ in range(ITERATIONS)]
    finally:
        algo_obj.stop()
    # The first row of an off-policy algorithm may precede its learner's first update (no ν yet).
    nu_lane = [r[per_constraint(NU, "lane")] for r in rows if per_constraint(NU, "lane") in r]
    nu_hazard = [r[per_constraint(NU, "hazard")] for r in rows if per_constraint(NU, "hazard") in r]
    lane = [r[per_constraint(EPISODE_COST, "lane")] for r in rows]
    hazard = [r[per_constraint(EPISODE_COST, "hazard")] for r in rows]
    assert len(nu_lane) >= ITERATIONS - 2 and len(nu_hazard) == len(nu_lane)
    assert max(nu_lane) > 0.05, f"the lane's multiplier never rose: {nu_lane}"
    assert all(v <= 1e-6 for v in nu_hazard), f"the hazard's multiplier moved though its limit is slack: {nu_hazard}"
    assert max(lane[:2]) > 3 * LIMITS["lane"], f"the lane's limit did not bind at first: {lane}"
    tail = float(np.mean(lane[-TAIL:]))
    assert tail <= LIMITS["lane"], f"the lane's cost {tail:.1f} is over its limit ({lane})"
    assert max(hazard) < LIMITS["hazard"]
    # feasible is the joint rule (every constraint within its limit); the summed cost is reported beside
    last = rows[-1]
    assert last[FEASIBLE] == float(lane[-1] <= LIMITS["lane"] and hazard[-1] <= LIMITS["hazard"])
    assert last[EPISODE_COST] == pytest.approx(lane[-1] + hazard[-1], rel=1e-6)
    assert last[per_constraint(COST_LIMIT, "lane")] == LIMITS["lane"]


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["lac", "ppo_lag"])  # the off- and on-policy multipliers (lagrange.py: one path)
def test_nu_fixed_along_one_constraint_holds_it_and_the_others_learn(ray_session, algo):
    """The frontier along one constraint: ``nu_fixed_constraint`` holds that ν_k at ``nu_fixed`` on
    every iteration while the other constraint's multiplier steps on its own cost (the hazard's limit
    0: any hazard cost raises it)."""
    sets = {"constraints": {"hazard": 0.0, "lane": 10.0}, "nu_fixed": 0.5, "nu_fixed_constraint": "lane",
            **SETS.get(algo, {})}
    config = registry.build_config(algo, TASK, 0, sets, timesteps=100_000)
    algo_obj = config.build_algo()
    try:
        rows = [iteration_row(algo_obj.train()) for _ in range(3)]
    finally:
        algo_obj.stop()
    lane = [r[per_constraint(NU, "lane")] for r in rows if per_constraint(NU, "lane") in r]
    hazard = [r[per_constraint(NU, "hazard")] for r in rows if per_constraint(NU, "hazard") in r]
    assert lane and all(v == 0.5 for v in lane), lane
    assert max(hazard) > 0.0, hazard


def test_nu_fixed_constraint_names_one_of_several():
    for sets, needle in (({"nu_fixed": 0.5, "nu_fixed_constraint": "lane"}, "accepted: None"),
                         ({"constraints": {"hazard": 1.0, "lane": 2.0}, "nu_fixed_constraint": "lane"},
                          "accepted: one of hazard, lane with nu_fixed set"),
                         ({"constraints": {"hazard": 1.0, "lane": 2.0}, "nu_fixed": 0.5, "nu_fixed_constraint": "x"},
                          "nu_fixed_constraint='x'")):
        with pytest.raises(ValueError, match=needle):
            registry.build_config("ppo_lag", TASK, 0, sets, timesteps=10_000)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["lac", "ppo_lag"])
def test_a_checkpoint_with_several_constraints_restores_every_multiplier(ray_session, algo, tmp_path):
    """Each ν_k, its rule's state (Adam's moments, LAC's bound) and the learner's cost window come
    back from a checkpoint as they were saved, on a fresh algorithm built from the same config."""
    config = registry.build_config(algo, TASK, 0, {"constraints": LIMITS, **SETS.get(algo, {})}, timesteps=100_000)
    first = config.build_algo()
    try:
        for _ in range(3):
            first.train()
        first.save_to_path(str(tmp_path / "ckpt"))
        saved = first.learner_group._learner
        nu, states = saved.module["default_policy"].nu.clone(), saved.multipliers["default_policy"].get_state()
        window = [list(map(float, c)) for c in getattr(saved, "cost_windows", {}).get("default_policy", [])]
    finally:
        first.stop()
    assert nu.shape == (2,) and len(states["constraints"]) == 2
    second = config.build_algo()
    try:
        second.restore_from_path(str(tmp_path / "ckpt"))
        learner = second.learner_group._learner
        assert learner.module["default_policy"].nu.tolist() == nu.tolist()
        assert learner.multipliers["default_policy"].get_state() == states
        assert [list(map(float, c)) for c in getattr(learner, "cost_windows", {}).get("default_policy", [])] == window
        # the multipliers write the restored buffer (bound to it again), not the one built before the restore
        learner.multipliers["default_policy"].step([1e6, 1e6])
        assert (learner.module["default_policy"].nu > nu).all()
    finally:
        second.stop()
