"""FOCOPS-convention MuJoCo tasks: sizes, seeding, planar-speed costs, HumanoidCircle."""

import pickle

import gymnasium as gym
import numpy as np
import pytest

from lac_rllib.tasks import get_task, mujoco_tasks
from lac_rllib.tasks.versions import runtime_versions

SPECS = {  # id: (obs, act, limit)
    "focops/AntVelocity-v0": (27, 8, 103.115),
    "focops/SwimmerVelocity-v0": (8, 2, 24.516),
    "focops/HumanoidVelocity-v0": (376, 17, 20.140),
    "focops/HumanoidCircle-v0": (378, 17, 50.0),
}


def _com_xy(model, data):
    mass = model.body_mass
    return (np.sum(mass[:, None] * data.xipos, axis=0) / mass.sum())[:2]


PLANAR = {  # independent re-implementation of "the planar position" of each robot
    "focops/AntVelocity-v0": lambda m, d: d.xpos[m.body("torso").id][:2].copy(),
    "focops/SwimmerVelocity-v0": lambda m, d: d.qpos[:2].copy(),
    "focops/HumanoidVelocity-v0": _com_xy,
}


def test_specs():
    for task_id, (obs, act, limit) in SPECS.items():
        spec = get_task(task_id)
        assert (spec.obs_dim, spec.act_dim, spec.cost_limit) == (obs, act, limit)
        assert spec.episode_cost_discount == 0.99 and spec.preset == "mujoco"
    assert {t.id for t in mujoco_tasks.TASKS} == set(SPECS)


def test_unknown_id_names_the_closest_ids_and_where_all_are_listed():
    from lac_rllib.tasks import known_tasks

    with pytest.raises(ValueError, match="focops/AntVelocity-v0") as err:
        get_task("focops/AntCircle-v0")
    assert f"(all {len(known_tasks())}: docs/tasks.md)" in str(err.value)
    with pytest.raises(ValueError, match="HumanoidCircle"):
        mujoco_tasks.make_env({"task": "AntCircle"})


@pytest.mark.parametrize("task_id", list(SPECS))
def test_spaces_seeding_and_time_limit(task_id):
    spec = get_task(task_id)
    env = spec.make()
    assert env.observation_space.shape == (spec.obs_dim,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (spec.act_dim,)
    a, b, c = (env.reset(seed=s)[0] for s in (3, 3, 4))
    assert a.dtype == np.float32 and a.shape == (spec.obs_dim,)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert env._max_episode_steps == 1000
    assert gym.make(task_id).observation_space.shape == (spec.obs_dim,)


def test_episodes_are_truncated_at_1000_steps():
    env = get_task("focops/SwimmerVelocity-v0").make()  # Swimmer never terminates
    env.reset(seed=0)
    env.action_space.seed(0)
    for t in range(1, 1001):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        assert not term and trunc == (t == 1000)


@pytest.mark.parametrize("task_id", list(PLANAR))
def test_velocity_cost_is_planar_speed_from_simulator_state(task_id):
    env = get_task(task_id).make()
    sim = env.unwrapped
    env.action_space.seed(2)
    env.reset(seed=2)
    costs = []
    for _ in range(60):
        before = PLANAR[task_id](sim.model, sim.data)
        _, _, term, trunc, info = env.step(env.action_space.sample())
        vx, vy = (PLANAR[task_id](sim.model, sim.data) - before) / (
            sim.model.opt.timestep * sim.frame_skip
        )
        assert isinstance(info["cost"], float)
        assert info["cost"] == pytest.approx(np.hypot(vx, vy), rel=1e-12, abs=1e-12)
        # FOCOPS read the same speed from the v3 envs' info (same quantity in v4).
        assert info["cost"] == pytest.approx(np.hypot(info["x_velocity"], info["y_velocity"]))
        costs.append(info["cost"])
        if term or trunc:
            env.reset()
    assert max(costs) > 0.0


def test_velocity_cost_for_a_known_motion():
    """Airborne humanoid given a pure planar velocity: COM speed over the step = that speed."""
    env = get_task("focops/HumanoidVelocity-v0").make()
    sim = env.unwrapped
    env.reset(seed=0)
    qpos, qvel = sim.init_qpos.copy(), np.zeros(sim.model.nv)
    qpos[2] = 1.9  # feet off the ground: no horizontal external force
    qvel[0:2] = 0.6, -0.8
    sim.set_state(qpos, qvel)
    _, _, _, _, info = env.step(np.zeros(17, dtype=np.float32))
    assert info["cost"] == pytest.approx(1.0, abs=1e-6)


# ----------------------------------------------------------------- HumanoidCircle


def _circle():
    env = get_task("focops/HumanoidCircle-v0").make()
    return env, env.unwrapped


def test_circle_reset_on_radius_10_at_seeded_angles():
    env, sim = _circle()
    angles = []
    for seed in range(24):
        obs, _ = env.reset(seed=seed)
        x, y = sim.data.qpos[0], sim.data.qpos[1]
        assert np.hypot(x, y) == pytest.approx(10.0, abs=1e-12)
        assert obs[:2] == pytest.approx(np.float32([x, y]))  # x, y are observed
        angles.append(np.arctan2(y, x))
    quadrants = {int((a + np.pi) // (np.pi / 2)) for a in angles}
    assert quadrants == {0, 1, 2, 3}  # uniform angle, not a fixed start
    assert env.action_space == gym.spaces.Box(-0.4, 0.4, (17,), np.float32)


def test_circle_actions_are_clipped():
    env, _ = _circle()
    env.reset(seed=9)
    big = env.step(np.full(17, 5.0, dtype=np.float32))
    env.reset(seed=9)
    clipped = env.step(np.full(17, 0.4, dtype=np.float32))
    assert np.array_equal(big[0], clipped[0]) and big[1] == clipped[1]


def _set(sim, xyz, v_xy):
    qpos, qvel = sim.init_qpos.copy(), np.zeros(sim.model.nv)
    qpos[0:3] = xyz
    qvel[0:2] = v_xy
    sim.set_state(qpos, qvel)


@pytest.mark.parametrize(
    "xyz, v_xy",
    [((10.0, 0.0, 1.9), (0.0, 1.0)), ((0.0, 10.0, 1.9), (-1.0, 0.0)),
     ((-6.0, 6.0, 1.9), (0.5, 0.5)), ((2.0, -4.0, 1.9), (1.0, -2.0))],
)
def test_circle_reward_and_cost_hand_computed(xyz, v_xy):
    env, sim = _circle()
    env.reset(seed=0)
    _set(sim, xyz, v_xy)
    x0, y0 = _com_xy(sim.model, sim.data)
    _, reward, term, _, info = env.step(np.zeros(17, dtype=np.float32))
    # Airborne, zero joint velocities, zero torque: the COM moves at exactly v_xy.
    dt = 0.015
    vx, vy = v_xy
    x, y = x0 + vx * dt, y0 + vy * dt
    expected = (-vx * y + vy * x) / (1.0 + abs(np.hypot(x, y) - 10.0))
    assert reward == pytest.approx(expected, rel=1e-6, abs=1e-9)
    assert info["cost"] == float(abs(x) > 2.5)
    assert not term
    # And exactly the formula on the simulator's own state after the step.
    xa, ya = _com_xy(sim.model, sim.data)
    vxa, vya = (xa - x0) / dt, (ya - y0) / dt
    assert reward == pytest.approx((-vxa * ya + vya * xa) / (1 + abs(np.hypot(xa, ya) - 10)),
                                   rel=1e-12)


def test_circle_known_values():
    env, sim = _circle()
    env.reset(seed=0)
    _set(sim, (0.0, 10.0, 1.9), (-2.0, 0.0))  # counter-clockwise at the top of the circle
    _, reward, _, _, info = env.step(np.zeros(17, dtype=np.float32))
    assert reward == pytest.approx(20.0, rel=0.01) and info["cost"] == 0.0
    _set(sim, (0.0, 10.0, 1.9), (2.0, 0.0))  # clockwise: negative
    _, reward, _, _, info = env.step(np.zeros(17, dtype=np.float32))
    assert reward == pytest.approx(-20.0, rel=0.01) and info["cost"] == 0.0
    _set(sim, (10.0, 0.0, 1.9), (0.0, 0.0))  # standing still outside the band |x| <= 2.5
    _, reward, _, _, info = env.step(np.zeros(17, dtype=np.float32))
    assert abs(reward) < 1e-6 and info["cost"] == 1.0


def test_circle_keeps_healthy_termination():
    env, sim = _circle()
    env.reset(seed=0)
    _set(sim, (0.0, 10.0, 0.5), (0.0, 0.0))  # torso below 1.0: unhealthy
    _, _, term, _, _ = env.step(np.zeros(17, dtype=np.float32))
    assert term


def test_circle_env_pickles():
    env = mujoco_tasks.HumanoidCircleEnv()
    clone = pickle.loads(pickle.dumps(env))
    assert type(clone) is type(env) and clone.observation_space.shape == (378,)


def test_runtime_versions():
    v = runtime_versions()
    assert set(v) >= {"numpy", "mujoco", "gymnasium", "safety_gymnasium"}
    assert v["numpy"] == np.__version__ and v["gymnasium"] == gym.__version__
    assert all(isinstance(v[k], str) for k in ("numpy", "mujoco", "gymnasium"))
