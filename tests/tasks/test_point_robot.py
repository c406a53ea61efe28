"""The paper's Point robot (Safety-Gym's torque motor, ``robot_variant: safety_gym``) on the
Point tasks: it turns where Safety-Gymnasium's does not, the rest of the task is unchanged, both
backends step it alike, and the fingerprint names it."""

import numpy as np
import pytest

from lac_rllib.algorithms.registry import budget_fields, build_config
from lac_rllib.tasks import get_task
from lac_rllib.tasks.fingerprint import fingerprint
from lac_rllib.tasks.navigation_equality import compare


def _turn_rate(variant: str, u: float, settle: int = 150, steps: int = 50) -> float:
    env = get_task("SafetyPointGoal1-v0").make({"robot_variant": variant})
    task = env.unwrapped.task
    env.reset(seed=0)
    action = np.array([0.0, u], np.float32)
    for _ in range(settle):
        env.step(action)
    yaw = []
    for _ in range(steps):
        env.step(action)
        yaw.append(np.arctan2(task.agent.mat[1, 0], task.agent.mat[0, 0]))
    env.close()
    return float(np.mean(np.diff(np.unwrap(yaw))) / (task.model.opt.timestep * task.sim_conf.frameskip_binom_n))


def test_the_papers_point_turns_at_a_command_of_005_where_safety_gymnasiums_does_not():
    assert abs(_turn_rate("safety_gymnasium", 0.05)) < 1e-3
    assert _turn_rate("safety_gym", 0.05) == pytest.approx(1.0, abs=0.02)  # 0.1 · 0.05 / damping 0.005
    assert _turn_rate("safety_gym", 0.02) == pytest.approx(0.4, abs=0.02)  # below the force limit: 20 · u


def test_only_the_turn_actuator_changes():
    stock = get_task("SafetyPointGoal1-v0").make({})
    paper = get_task("SafetyPointGoal1-v0").make({"robot_variant": "safety_gym"})
    a, b = stock.unwrapped, paper.unwrapped
    for env in (stock, paper):
        env.reset(seed=5)
    ma, mb = a.task.model, b.task.model
    assert [ma.actuator(i).name for i in range(ma.nu)] == ["x", "z"]
    assert [mb.actuator(i).name for i in range(mb.nu)] == ["x", "rz"]
    assert np.array_equal(ma.body_pos, mb.body_pos) and (ma.nbody, ma.ngeom, ma.nsensor) == (mb.nbody, mb.ngeom,
                                                                                              mb.nsensor)
    assert a.task.world_info.layout.keys() == b.task.world_info.layout.keys()
    assert stock.observation_space == paper.observation_space and stock.action_space == paper.action_space


@pytest.mark.parametrize("env_id", ["SafetyPointGoal1-v0", "SafetyPointButton1-v0", "SafetyPointPush2-v0"])
def test_both_backends_step_the_papers_point_alike(env_id):
    c = compare(env_id, num_envs=2, vector_steps=200, seed=1, max_episode_steps=80,
                env_config={"robot_variant": "safety_gym"})
    assert c.identical and c.episodes == 4, c.line()


def test_the_variant_is_a_field_named_in_the_fingerprint_and_refused_off_point():
    sets = {**budget_fields("ppo_lag", "smoke", "safety_gym"), "robot_variant": "safety_gym"}
    assert build_config("ppo_lag", "SafetyPointGoal1-v0", 0, sets).env_config["robot_variant"] == "safety_gym"
    with pytest.raises(ValueError, match="robot_variant='safety_gym' on SafetyCarGoal1-v0: only the Point tasks"):
        build_config("ppo_lag", "SafetyCarGoal1-v0", 0, sets)
    assert fingerprint("SafetyPointGoal1-v0", {"robot_variant": "safety_gym"})["robot_variant"] == "safety_gym"
    assert fingerprint("SafetyPointGoal1-v0", {})["robot_variant"] == "safety_gymnasium"
    assert "robot_variant" not in fingerprint("SafetyCarGoal1-v0", {})
