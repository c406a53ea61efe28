"""Safety-Gymnasium tasks: registration, 5-tuple form with info["cost"], seeding, costs."""

import json
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

from lac_rllib.tasks import get_task, known_tasks, safety_gym, safety_gym_compat

NAV = {  # id: (obs, act)
    "SafetyPointGoal1-v0": (60, 2),
    "SafetyCarGoal1-v0": (72, 2),
    "SafetyPointButton1-v0": (76, 2),
    "SafetyCarButton1-v0": (88, 2),
}
VEL = {  # id: (obs, act, threshold, planar position of the cost, speed or vx)
    "SafetyAntVelocity-v1": (27, 8, 2.6222, "torso", "speed"),
    "SafetySwimmerVelocity-v1": (8, 2, 0.2282, "qpos", "vx"),
    "SafetyHumanoidVelocity-v1": (376, 17, 1.4149, "com", "speed"),
}


def _rollout(env, seed: int, steps: int):
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, rew, term, trunc, info = env.step(env.action_space.sample())
        out.append((obs, rew, info["cost"], term, trunc))
        if term or trunc:
            break
    return out


def test_specs():
    for task_id, (obs, act) in NAV.items():
        spec = get_task(task_id)
        assert (spec.obs_dim, spec.act_dim) == (obs, act)
        assert (spec.cost_limit, spec.episode_cost_discount, spec.preset) == (25, 1.0, "safety_gym")
    for task_id, (obs, act, *_rest) in VEL.items():
        spec = get_task(task_id)
        assert (spec.obs_dim, spec.act_dim) == (obs, act)
        assert (spec.cost_limit, spec.episode_cost_discount, spec.preset) == (25, 1.0, "mujoco")
    assert set(NAV) | set(VEL) == {t.id for t in safety_gym.TASKS}
    assert set(NAV) | set(VEL) <= set(known_tasks())


def test_unknown_id_lists_known_ids():
    with pytest.raises(ValueError, match="SafetyCarButton1-v0") as err:
        get_task("SafetyPointGoal3-v0")
    assert "focops/HumanoidCircle-v0" in str(err.value)
    with pytest.raises(ValueError, match="SafetyPointGoal1-v0"):
        safety_gym.make_env({"env_id": "SafetyPointGoal3-v0"})


def _check_spaces_and_time_limit(env, spec):
    assert env.observation_space.shape == (spec.obs_dim,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (spec.act_dim,) and env.action_space.dtype == np.float32
    limits = [w._max_episode_steps for w in _wrappers(env) if hasattr(w, "_max_episode_steps")]
    assert limits == [1000]


@pytest.mark.parametrize("task_id", list(VEL))
def test_spaces_seeding_and_time_limit(task_id):
    # (navigation tasks: checked in test_navigation_matches_safety_gymnasium..., their resets
    # cost ~1 s each: they rebuild the MuJoCo model)
    spec = get_task(task_id)
    env = spec.make()
    _check_spaces_and_time_limit(env, spec)
    a, b, c = (env.reset(seed=s)[0] for s in (11, 11, 12))
    assert a.dtype == np.float32 and a.shape == (spec.obs_dim,)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def _wrappers(env):
    while True:
        yield env
        if not hasattr(env, "env"):
            return
        env = env.env


@pytest.mark.parametrize("task_id", list(NAV))
def test_navigation_matches_safety_gymnasium_and_costs_are_binary(task_id):
    """Our 5-tuple env reproduces safety_gymnasium's own 6-tuple env step by step; spaces,
    time limit and seeding (same seed → same obs in two envs; other seed → other obs)."""
    sg = safety_gym_compat.apply()
    spec = get_task(task_id)
    ours = spec.make()
    _check_spaces_and_time_limit(ours, spec)
    raw = sg.make(task_id)
    first, _ = ours.reset(seed=5)
    raw_obs, _ = raw.reset(seed=5)
    assert first.dtype == np.float32 and first.shape == (spec.obs_dim,)
    assert np.array_equal(first, raw_obs.astype(np.float32))
    rng = np.random.default_rng(5)
    for _ in range(150):
        action = rng.uniform(-1, 1, size=2).astype(np.float32)
        o, r, te, tr, info = ours.step(action)
        raw_obs, rew, cost, term, trunc, _ = raw.step(action.astype(np.float64))
        assert np.array_equal(o, raw_obs.astype(np.float32))
        assert (r, info["cost"], te, tr) == (rew, cost, term, trunc)
        assert isinstance(info["cost"], float) and info["cost"] in (0.0, 1.0)
    assert not np.array_equal(ours.reset(seed=6)[0], first)


def _teleport_agent(builder, xy):
    """Move the navigation agent (Point: x/y slide joints; Car: free joint) to ``xy``."""
    import mujoco

    model, data = builder.task.model, builder.task.data
    delta = np.asarray(xy) - data.body("agent").xpos[:2]
    names = {model.joint(i).name for i in range(model.njnt)}
    if "x" in names:  # slide joints along the (placement-rotated) axes data.xaxis
        jx, jy = model.joint("x").id, model.joint("y").id
        axes = np.stack([data.xaxis[jx][:2], data.xaxis[jy][:2]], axis=1)
        dq = np.linalg.solve(axes, delta)
        data.qpos[model.jnt_qposadr[jx]] += dq[0]
        data.qpos[model.jnt_qposadr[jy]] += dq[1]
    else:  # free joint: world position
        adr = model.joint("agent").qposadr[0]
        data.qpos[adr : adr + 2] += delta
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)


@pytest.mark.parametrize("task_id", list(NAV))
def test_navigation_cost_follows_hazards(task_id):
    """cost = 1 whenever the agent is inside a hazard (Goal1: iff; Button1: also gremlins,
    wrong buttons), recomputed from body positions in the simulator."""
    env = get_task(task_id).make()
    builder = env.unwrapped
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    hazards = builder.task.hazards
    start = builder.task.data.body("agent").xpos[:2].copy()  # layouts start cost-free
    seen = set()
    for step in range(45):
        data = builder.task.data
        if step % 15 == 0:  # drop the agent onto a hazard ...
            _teleport_agent(builder, data.body(f"hazard{step // 15}").xpos[:2])
            assert np.allclose(data.body("agent").xpos[:2], data.body(f"hazard{step // 15}").xpos[:2])
        elif step % 15 == 8:  # ... and back to its start
            _teleport_agent(builder, start)
        _, _, term, trunc, info = env.step(rng.uniform(-0.2, 0.2, size=2).astype(np.float32))
        agent = data.body("agent").xpos[:2]
        in_hazard = any(
            np.linalg.norm(agent - data.body(f"hazard{i}").xpos[:2]) <= hazards.size
            for i in range(hazards.num)
        )
        if "Goal" in task_id:
            assert info["cost"] == float(in_hazard)
        elif in_hazard:
            assert info["cost"] == 1.0
        seen.add(info["cost"])
        assert not term
    assert 1.0 in seen and ("Button" in task_id or 0.0 in seen)


def _planar(kind, model, data):
    if kind == "torso":
        return data.body("torso").xpos[:2].copy()
    if kind == "qpos":
        return data.qpos[:2].copy()
    mass = model.body_mass
    return (np.sum(mass[:, None] * data.xipos, axis=0) / mass.sum())[:2]


@pytest.mark.parametrize("task_id", list(VEL))
def test_velocity_v1_cost_is_threshold_indicator(task_id):
    _obs, _act, threshold, kind, measure = VEL[task_id]
    env = get_task(task_id).make()
    sim = env.unwrapped
    env.action_space.seed(1)
    env.reset(seed=1)
    seen = set()
    for step in range(40):
        if step % 10 in (0, 5):  # push the robot fast / stop it: both cost values occur
            qpos, qvel = sim.data.qpos.copy(), sim.data.qvel.copy()
            qvel[:] = 0.0
            qvel[0] = 3.0 * threshold if step % 10 == 0 else 0.0
            if kind != "qpos":
                qpos[2] = {"torso": 0.9, "com": 1.9}[kind]  # airborne, still healthy
            sim.set_state(qpos, qvel)
        before = _planar(kind, sim.model, sim.data)
        _, _, term, trunc, info = env.step(env.action_space.sample())
        vx, vy = (_planar(kind, sim.model, sim.data) - before) / sim.dt
        value = np.hypot(vx, vy) if measure == "speed" else vx
        assert info["cost"] == float(value > threshold)
        seen.add(info["cost"])
        if term or trunc:
            env.reset()
    assert seen == {0.0, 1.0}


def test_gym_make_gives_five_tuple_env():
    env = gym.make("SafetyCarGoal1-v0")
    env.reset(seed=0)
    out = env.step(env.action_space.sample())
    assert len(out) == 5 and isinstance(out[4]["cost"], float)


def test_builds_in_a_fresh_process():
    """As an RLlib env runner does: import the factory module by string, then build."""
    code = textwrap.dedent(
        """
        import json, gymnasium as gym
        import lac_rllib.tasks
        env = gym.make("SafetyCarButton1-v0")  # via gymnasium's registry
        obs, _ = env.reset(seed=0)
        o, r, te, tr, info = env.step(env.action_space.sample())
        from lac_rllib.tasks.registry import get_task
        env2 = get_task("SafetySwimmerVelocity-v1").make({"num_envs": 1})  # extra keys ignored
        env2.reset(seed=0)
        print(json.dumps({"shape": list(o.shape), "cost": info["cost"],
                          "dtype": str(o.dtype), "n": len(env2.step(env2.action_space.sample()))}))
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out == {"shape": [88], "cost": out["cost"], "dtype": "float32", "n": 5}
    assert out["cost"] in (0.0, 1.0)
