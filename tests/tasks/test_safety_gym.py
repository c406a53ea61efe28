"""Safety-Gymnasium tasks: registration, 5-tuple form with info["cost"], seeding, costs."""

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.tasks import TaskSpec, get_task, known_tasks, safety_gym, safety_gym_compat
from lac_rllib.tasks.constraints import Constraint

DOCS_TASKS = Path(__file__).resolve().parents[2] / "docs" / "tasks.md"

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
    assert set(NAV) | set(VEL) <= {t.id for t in safety_gym.TASKS}
    assert set(NAV) | set(VEL) <= set(known_tasks())


def test_unknown_id_names_the_closest_known_ids():
    with pytest.raises(ValueError, match=r"closest known tasks: SafetyPointGoal\d-v0, ") as err:
        get_task("SafetyPointGoal3-v0")
    assert "focops/HumanoidCircle-v0" not in str(err.value) and "docs/tasks.md" in str(err.value)
    with pytest.raises(ValueError, match="SafetyPointGoal1-v0"):
        safety_gym.make_env({"env_id": "SafetyPointGoal3-v0"})


def _check_spaces_and_time_limit(env, spec):
    assert env.observation_space.shape == (spec.obs_dim,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (spec.act_dim,) and env.action_space.dtype == np.float32
    limits = [w._max_episode_steps for w in _wrappers(env) if hasattr(w, "_max_episode_steps")]
    assert limits == [safety_gym.episode_steps(spec.id)] == [spec.episode_steps]  # what the sweep plan counts


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


# --------------------------------------------------------------------------- every task (issue 22)

ROBOTS = ("Point", "Car", "Doggo", "Racecar", "Ant")
NAV_FAMILIES = ("Goal", "Button", "Push", "Circle")
VELOCITY_ROBOTS = ("Ant", "HalfCheetah", "Hopper", "Humanoid", "Swimmer", "Walker2d")
ALL_NAV = [f"Safety{r}{f}{lvl}-v0" for f in NAV_FAMILIES for lvl in (0, 1, 2) for r in ROBOTS]
ALL_NAV += [f"Safety{r}Run0-v0" for r in ROBOTS]
ALL_VEL = [f"Safety{r}Velocity-v1" for r in VELOCITY_ROBOTS]


def _safety_ids() -> set[str]:
    return {t for t in known_tasks() if get_task(t).factory == safety_gym.FACTORY}


def test_original_seven_task_specs_unchanged():
    """Other code and evidence rely on these exact values."""
    def nav(env_id, obs, hazards, family):
        return TaskSpec(env_id, safety_gym.FACTORY, 25.0, 1.0, "safety_gym", obs, 2,
                        f'safety_gymnasium info["cost"] in {{0,1}} ({hazards}), summed',
                        {"env_id": env_id}, family,
                        constraints=safety_gym.NAV_CONSTRAINTS[f"{family}1"])  # the constraints came later

    def vel(env_id, obs, act, indicator):
        return TaskSpec(env_id, safety_gym.FACTORY, 25.0, 1.0, "mujoco", obs, act,
                        f"safety_gymnasium velocity v1 indicator {indicator}, summed", {"env_id": env_id},
                        constraints=(Constraint("velocity", ("cost",)),))

    button = "hazards, gremlins, wrong buttons"
    expected = [
        nav("SafetyPointGoal1-v0", 60, "hazards", "Goal"),
        nav("SafetyCarGoal1-v0", 72, "hazards", "Goal"),
        nav("SafetyPointButton1-v0", 76, button, "Button"),
        nav("SafetyCarButton1-v0", 88, button, "Button"),
        vel("SafetyAntVelocity-v1", 27, 8, "1[sqrt(vx^2+vy^2) > 2.6222]"),
        vel("SafetySwimmerVelocity-v1", 8, 2, "1[vx > 0.2282]"),
        vel("SafetyHumanoidVelocity-v1", 376, 17, "1[sqrt(vx^2+vy^2) > 1.4149]"),
    ]
    for spec in expected:
        assert get_task(spec.id) == spec
    # LAC's T = 50 on the Button tasks (Table 5), now its override for the family.
    assert LACConfig().task("SafetyCarButton1-v0").langevin_steps == 50
    assert LACConfig().task("SafetyCarGoal1-v0").langevin_steps == 30


def test_every_navigation_and_velocity_task_is_registered():
    assert _safety_ids() == set(ALL_NAV) | set(ALL_VEL)
    assert len(ALL_NAV) == 65 and len(ALL_VEL) == 6
    for task_id in ALL_NAV + ALL_VEL:
        spec = get_task(task_id)
        nav = task_id in ALL_NAV
        assert (spec.cost_limit, spec.episode_cost_discount) == (25.0, 1.0)
        assert spec.preset == ("safety_gym" if nav else "mujoco")
        assert spec.kwargs == {"env_id": task_id}
        assert spec.family == (re.match(r"Safety[A-Z][a-z]+([A-Z][a-z]+)\d", task_id)[1] if nav else "")
        assert spec.cost_source.startswith("safety_gymnasium ")
        assert ("always 0" in spec.cost_source) == bool(re.search(r"(Goal|Button|Push|Circle)0-", task_id))
        assert safety_gym.episode_steps(task_id) == (500 if re.search(r"(Circle|Run)\d", task_id) else 1000)


def _sampled_ids() -> list[str]:
    """One id per (robot, navigation family), the level rotating so that every level of every
    family is sampled by some robot; plus every velocity task."""
    ids = [f"Safety{r}{f}{(i + j) % 3}-v0" for j, f in enumerate(NAV_FAMILIES) for i, r in enumerate(ROBOTS)]
    return ids + [f"Safety{r}Run0-v0" for r in ROBOTS] + ALL_VEL


def test_sample_covers_every_family_and_level():
    split = [re.fullmatch(r"Safety(Point|Car|Doggo|Racecar|Ant)(\w+\d)-v0", t) for t in _sampled_ids()]
    sampled = [m.groups() for m in split if m]
    assert {task for _, task in sampled} == {f"{f}{lvl}" for f in NAV_FAMILIES for lvl in (0, 1, 2)} | {"Run0"}
    assert {robot for robot, _ in sampled} == set(ROBOTS)
    assert len(sampled) == len(set(sampled)) == 25


@pytest.mark.parametrize("task_id", _sampled_ids())
def test_table_matches_the_env(task_id):
    """The registry's obs/act sizes and episode length (a table, so that importing the registry
    stays cheap) are what the env reports; safety_gymnasium's own episode length agrees."""
    spec = get_task(task_id)
    env = spec.make()
    _check_spaces_and_time_limit(env, spec)
    assert safety_gym_compat.safety_spec(task_id).max_episode_steps == safety_gym.episode_steps(task_id)
    if task_id in ALL_NAV:
        assert env.unwrapped.task.num_steps == safety_gym.episode_steps(task_id)
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.shape == (spec.obs_dim,)
    env.action_space.seed(0)
    for _ in range(5):
        obs, _, _, _, info = env.step(env.action_space.sample())
        assert obs.shape == (spec.obs_dim,) and isinstance(info["cost"], float)
        assert info["cost"] in (0.0, 1.0)


def _docs_rows() -> dict[str, list[str]]:
    rows = {}
    for line in DOCS_TASKS.read_text(encoding="utf-8").splitlines():
        if m := re.match(r"\| `(Safety[^`]+)` \|", line):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            assert m.group(1) not in rows, f"{m.group(1)} listed twice"
            rows[m.group(1)] = cells
    return rows


def test_docs_tasks_md_lists_exactly_the_registered_ids():
    rows = _docs_rows()
    assert set(rows) == _safety_ids()
    for task_id, (_id, _family, robot, _level, obs, act, steps, limit, preset, _cost) in rows.items():
        spec = get_task(task_id)
        assert robot in task_id
        assert (int(obs), int(act), int(steps)) == (spec.obs_dim, spec.act_dim, safety_gym.episode_steps(task_id))
        assert float(limit) == spec.cost_limit
        assert preset.split("`")[1] == spec.preset
        assert ("T = 50" in preset) == ("langevin_steps" in LACConfig.TASK_FAMILY_OVERRIDES.get(spec.family, {}))


def test_new_navigation_tasks_step_and_cost():
    """Two ids beyond the original seven: cost 1 on a hazard (Goal2) and outside the walls
    (Circle1), 0 back at the start; Circle1 ends after 500 steps."""
    for task_id, target in (("SafetyPointGoal2-v0", "hazard"), ("SafetyCarCircle1-v0", (2.0, 0.0))):
        env = get_task(task_id).make()
        builder = env.unwrapped
        obs, _ = env.reset(seed=4)
        start = builder.task.data.body("agent").xpos[:2].copy()
        costs = []
        for step in range(20):
            if step == 5:
                xy = builder.task.data.body("hazard0").xpos[:2] if target == "hazard" else target
                _teleport_agent(builder, xy)
            elif step == 12:
                _teleport_agent(builder, start)
            obs, _, term, trunc, info = env.step(np.zeros(2, np.float32))
            assert isinstance(info["cost"], float) and obs.shape == (get_task(task_id).obs_dim,)
            costs.append(info["cost"])
            assert not (term or trunc)
        assert costs[5] == 1.0 and costs[12:] == [0.0] * 8 and costs[:5] == [0.0] * 5
    n = 20
    while not (trunc or term):
        _, _, term, trunc, _ = env.step(np.zeros(2, np.float32))
        n += 1
    assert (n, trunc, term) == (500, True, False)


def test_doggo_and_ant_robots_build_with_the_angle_sensor_fix():
    """Fix 6: float() of their shape-(1,) hinge-angle sensors, numpy >= 2.4."""
    import builtins

    safety_gym_compat.apply()
    base_agent = sys.modules["safety_gymnasium.bases.base_agent"]
    assert base_agent.float is safety_gym_compat._scalar_float and builtins.float is float
    assert safety_gym_compat._scalar_float(np.array([0.25])) == 0.25
    assert safety_gym_compat._scalar_float("2") == 2.0
    with pytest.raises(TypeError):
        safety_gym_compat._scalar_float(np.zeros(2))
    safety_gym_compat.apply()
    assert base_agent.float is safety_gym_compat._scalar_float  # idempotent
    for task_id in ("SafetyDoggoGoal1-v0", "SafetyAntButton1-v0"):
        env = get_task(task_id).make()
        obs, _ = env.reset(seed=0)
        assert obs.shape == (get_task(task_id).obs_dim,) and np.all(np.isfinite(obs))


def test_every_navigation_task_declares_its_step_cost():
    """The sweep plan's per-task step cost (TaskSpec.step_cost): PointGoal1 is the reference, every
    navigation id has its measured value, and a Button1 step costs more than a Goal1 step per robot."""
    nav = [t for t in _safety_ids() if "Velocity" not in t]
    assert get_task("SafetyPointGoal1-v0").step_cost == 1.0
    assert all(0.1 < get_task(t).step_cost < 50 for t in nav)
    assert len({get_task(t).step_cost for t in nav}) > 30  # measured per id, not one default
    for robot in safety_gym.NAV_ROBOTS:
        goal, button = (get_task(safety_gym.nav_id(robot, task)).step_cost for task in ("Goal1", "Button1"))
        assert button > goal, robot
