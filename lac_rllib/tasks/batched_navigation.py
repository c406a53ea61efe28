"""N Safety-Gymnasium navigation envs stepped as one vector env, bit-identical to the stock ones.

A stock SafetyPointGoal1-v0 step spends ~20% of its time in MuJoCo and the rest in ~830 Python
calls of safety_gymnasium's task layer (../docs/speed.md). Here each step runs the physics of every
env (its ``mj_step`` calls and one ``mj_forward``) and then the task layer once for all N envs as
array operations (lac_rllib/tasks/navigation_layer.py): lidar, reward, the ``cost_*`` indicators,
the goal test, termination and truncation.

What stays safety_gymnasium's own code, run per env, because it is rare and its random stream
must be untouched: ``reset`` (layout sampling with its placement retries, the world rebuilt) and
the goal's resampling when it is reached. Each env is the stock env of lac_rllib/tasks/safety_gym.py
(compat shim, light resets); this class only replaces its ``step``. The random draws a stock step
makes (the frame-skip binomial) are made on each env's own generator, in the same order, so every
later layout is the same.

Equality with the stock envs (every observation, reward, cost, ``cost_*`` key, terminated,
truncated and every reset's layout) is tested per task id in tests/tasks/test_batched_navigation.py
and over long streams by benchmarks/batched_equality.py.

Autoreset follows gymnasium's ``SyncVectorEnv`` (``AutoresetMode.NEXT_STEP``), the mode RLlib's
env runner expects: the step after an episode ends resets that env and returns its first
observation with reward 0.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from lac_rllib.tasks import navigation_layer as layer

#: Task families and robots this class steps; the other navigation ids run on the stock backend.
FAMILIES = ("Goal",)
ROBOTS = ("Point", "Car")


def supports(robot: str, task: str) -> bool:
    """Whether ``Safety{robot}{task}-v0`` runs on the batched backend."""
    return robot in ROBOTS and task.rstrip("0123456789") in FAMILIES and task[-1] in "012"


@dataclasses.dataclass
class _Sim:
    """One env's handles into its current world (rebuilt at every reset)."""

    task: Any  #: safety_gymnasium's task object (its model and data change at each reset)
    model: Any
    data: Any
    rng: np.random.RandomState  #: the task's own generator
    bodies: np.ndarray  #: body ids read each step: the agent, then each lidar group's objects in order
    raw: np.ndarray  #: sensordata addresses of the sensors read as they are, in the observation's order
    quats: list  #: sensordata addresses of the ball-joint quaternions (observed as rotation matrices)
    vase_geom: np.ndarray | None  #: per geom id: a vase's geom (its name starts with "vase")
    agent_geom: np.ndarray | None  #: per geom id: one of the agent's geoms
    # Views of the data's arrays, taken once (each attribute access of MjData makes a new view).
    ctrl: np.ndarray = None
    xpos: np.ndarray = None
    xmat: np.ndarray = None
    sensordata: np.ndarray = None

    def __post_init__(self):
        self.ctrl, self.xpos, self.xmat = self.data.ctrl, self.data.xpos, self.data.xmat
        self.sensordata = self.data.sensordata


@dataclasses.dataclass(frozen=True)
class _Layout:
    """Where each piece of the flat observation comes from (the same for every env of a task)."""

    groups: dict  #: lidar group → slice of ``_Sim.bodies`` (the agent is row 0)
    columns: list  #: per observation key in order: ("raw", raw slice) | ("quat", k) | ("lidar", group)


class BatchedNavigationEnv(VectorEnv):
    """``num_envs`` envs of one navigation task (``env_id``), stepped together."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, env_id: str, num_envs: int, max_episode_steps: int | None = None,
                 light_resets: bool = True) -> None:
        from lac_rllib.tasks.safety_gym import episode_steps, make_env

        self.env_id, self.num_envs = env_id, int(num_envs)
        cfg = {"env_id": env_id, "light_resets": light_resets}
        if max_episode_steps is not None:
            cfg["max_episode_steps"] = int(max_episode_steps)
        self.envs = [make_env(cfg) for _ in range(self.num_envs)]
        first = self.envs[0]
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._inner_dtype = first._inner_action_dtype
        task = first.unwrapped.task
        self._task = task  # its configuration (sizes, rewards, lidar): the same in every env of the id
        self._horizon = min(task.num_steps, int(max_episode_steps or episode_steps(env_id)))
        self._layout = _layout(task)
        self._cost_keys = _cost_keys(task)
        self._sims: list[_Sim | None] = [None] * self.num_envs
        self._steps = np.zeros(self.num_envs, np.int64)
        self._last_dist = np.zeros(self.num_envs)
        self._autoreset = np.zeros(self.num_envs, bool)

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        """Every env reset by its stock code, seeded as ``SyncVectorEnv`` seeds: ``seed + i``."""
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} envs; accepted: one per env")
        obs, infos = np.zeros(self.observation_space.shape, self.observation_space.dtype), {}
        for i, s in enumerate(seeds):
            obs[i], info = self._reset_one(i, s, options)
            infos = self._add_info(infos, info, i)
        self._autoreset[:] = False
        return obs, infos

    def _reset_one(self, i: int, seed, options):
        o, info = self.envs[i].reset(seed=seed, options=options)
        self._sims[i] = _attach(self.envs[i].unwrapped.task, self._layout)
        self._steps[i] = 0
        self._last_dist[i] = self._sims[i].task.last_dist_goal
        return o, info

    # ------------------------------------------------------------------ step
    def step(self, actions):
        n = self.num_envs
        obs = np.zeros(self.observation_space.shape, self.observation_space.dtype)
        rewards = np.zeros(n)
        terminated, truncated = np.zeros(n, bool), np.zeros(n, bool)
        infos: dict = {}
        for i in np.flatnonzero(self._autoreset):  # NEXT_STEP: this step only resets
            obs[i], info = self._reset_one(i, None, None)
            infos = self._add_info(infos, info, i)
        live = np.flatnonzero(~self._autoreset)
        if live.size:
            infos = self._step_live(live, np.asarray(actions, self._inner_dtype)[live], obs, rewards, terminated,
                                    truncated, infos)
        self._autoreset = terminated | truncated
        return obs, rewards, terminated, truncated, infos

    def _step_live(self, live, actions, obs, rewards, terminated, truncated, infos) -> dict:
        sims = [self._sims[i] for i in live]
        task, layout = self._task, self._layout
        # Underlying.simulation_forward: the control clipped to the actuators' range, the frame-skip
        # draw on the env's own generator, the steps, one forward (the stock step's later forwards
        # recompute the same derived fields from the same state).
        span = task.model.actuator_ctrlrange
        ctrl = np.clip(actions, span[:, 0], span[:, 1])
        skip_n, skip_p = task.sim_conf.frameskip_binom_n, task.sim_conf.frameskip_binom_p
        step, forward = mujoco.mj_step, mujoco.mj_forward
        for j, sim in enumerate(sims):
            m, d = sim.model, sim.data
            sim.ctrl[:] = ctrl[j]
            frames = sim.rng.binomial(skip_n, skip_p)
            if frames:  # mj_step's nstep: the same steps, one call
                step(m, d, frames)
            forward(m, d)
        xpos = np.stack([s.xpos[s.bodies] for s in sims])
        agent = xpos[:, 0]
        # Reward (GoalLevel0.calculate_reward): the progress towards the goal, plus reward_goal inside it.
        dist = layer.dist_xy(xpos[:, layout.groups["goal"]], agent)[:, 0]
        reward = (self._last_dist[live] - dist) * task.goal.reward_distance
        self._last_dist[live] = dist
        achieved = dist <= task.goal.size
        reward = np.where(achieved, reward + task.goal.reward_goal, reward)
        rewards[live] = layer.clip_reward(reward, task.reward_conf.reward_clip)
        costs = self._costs(sims, xpos)
        for key, value in costs.items():  # the infos SyncVectorEnv would gather, key by key
            infos = self._add_column(infos, key, value, live)
        infos = self._add_column(infos, "cost", costs["cost_sum"], live)
        for j in np.flatnonzero(achieved):  # the goal resampled by safety_gymnasium's own code
            i, sim = live[j], sims[j]
            sim.task.update_layout()
            try:
                sim.task.update_world()
                self._last_dist[i] = sim.task.last_dist_goal
            except _resampling_error():
                terminated[i] = True
            infos = self._add_info(infos, {"goal_met": True}, i)
        if achieved.any():
            xpos = np.stack([s.xpos[s.bodies] for s in sims])
        self._steps[live] += 1
        truncated[live] = self._steps[live] >= self._horizon
        obs[live] = self._observe(sims, xpos)
        return infos

    def _add_column(self, infos: dict, key: str, values: np.ndarray, rows: np.ndarray) -> dict:
        """``key``'s float values for the envs ``rows``, as ``_add_info`` per env would gather them."""
        column = infos.get(key)
        if column is None:
            column, mask = np.zeros(self.num_envs), np.zeros(self.num_envs, np.bool_)
        else:
            mask = infos[f"_{key}"]
        column[rows], mask[rows] = values, True
        infos[key], infos[f"_{key}"] = column, mask
        return infos

    def _costs(self, sims, xpos) -> dict[str, np.ndarray]:
        """The ``cost_*`` indicators in ``BaseTask.calculate_cost``'s order, and their sum's."""
        out = {}
        agent = xpos[:, 0]
        for name, ob in self._cost_keys:
            if name == "hazards":
                dist = layer.dist_xy(xpos[:, self._layout.groups["hazards"]], agent)
                out["cost_hazards"] = layer.hazard_violation(dist, ob.size).astype(float)
            elif name == "vases":
                out |= _vase_costs(sims, ob)
        total = np.any(np.stack(list(out.values())) > 0, axis=0) if out else np.zeros(len(sims), bool)
        out["cost_sum"] = total.astype(float)
        return out

    def _observe(self, sims, xpos) -> np.ndarray:
        """``BaseTask.obs`` flattened: the sensors, then each lidar, in the observation's order."""
        c = self._task.lidar_conf
        mat = np.stack([s.xmat[s.bodies[0]] for s in sims]).reshape(-1, 3, 3)
        raw = np.stack([s.sensordata[s.raw] for s in sims])
        parts = []
        for kind, what in self._layout.columns:
            if kind == "raw":
                parts.append(raw[:, what])
            elif kind == "quat":
                parts.append(np.stack([_quat2mat(s.data.sensordata[s.quats[what]]) for s in sims]))
            else:
                ego = layer.ego_xy(xpos[:, self._layout.groups[what]], xpos[:, 0], mat)
                parts.append(layer.pseudo_lidar(ego, c.num_bins, c.max_dist, c.exp_gain, c.alias))
        return np.concatenate(parts, axis=1).astype(self.observation_space.dtype)

    def close_extras(self, **kwargs) -> None:
        for env in self.envs:
            env.close()


def _lidar_bodies(ob) -> list[str]:
    """The bodies whose positions an obstacle's lidar sees (its ``pos``)."""
    return ["goal"] if ob.name == "goal" else [f"{ob.name[:-1]}{k}" for k in range(ob.num)]


def _layout(task) -> _Layout:
    groups, at = {}, 1
    for ob in task._obstacles:
        if ob.is_lidar_observed or (ob.name == "hazards" and ob.is_constrained):
            k = len(_lidar_bodies(ob))
            groups[ob.name] = slice(at, at + k)
            at += k
    columns, raw_at = [], 0
    quats = task.agent.sensor_info.ballquat_names
    for key, space in task.obs_info.obs_space_dict.items():
        if key.endswith("_lidar"):
            columns.append(("lidar", key[: -len("_lidar")]))
        elif key in quats:
            columns.append(("quat", quats.index(key)))
        else:
            dim = int(np.prod(space.shape))
            columns.append(("raw", slice(raw_at, raw_at + dim)))
            raw_at += dim
    return _Layout(groups=groups, columns=columns)


def _cost_keys(task) -> list:
    """(name, obstacle) of each constrained obstacle, in ``calculate_cost``'s order."""
    out = []
    for ob in task._obstacles:
        if getattr(ob, "is_constrained", False):
            if ob.name not in ("hazards", "vases"):
                raise NotImplementedError(f"the batched backend has no cost for {ob.name}")
            if ob.name == "vases" and ob.displace_cost:
                raise NotImplementedError("vases.displace_cost > 0 is not batched")
            out.append((ob.name, ob))
    if task._is_load_static_geoms and task.static_geoms_contact_cost:
        raise NotImplementedError("static geoms' contact cost is not batched")
    return out


def _attach(task, layout: _Layout) -> _Sim:
    """Handles into ``task``'s current world, read in the stock observation's order."""
    model = task.model
    names = ["agent"] + [b for ob in task._obstacles if ob.name in layout.groups for b in _lidar_bodies(ob)]
    raw, quats = [], []
    info = task.agent.sensor_info
    for key in task.obs_info.obs_space_dict.keys():
        if key.endswith("_lidar"):
            continue
        sid = model.sensor(key).id
        adr = np.arange(model.sensor_adr[sid], model.sensor_adr[sid] + model.sensor_dim[sid])
        (quats.append(adr) if key in info.ballquat_names else raw.append(adr))
    vase_geom = agent_geom = None
    if getattr(task, "vases", None) is not None and task.vases.is_constrained:
        geoms = [model.geom(g).name for g in range(model.ngeom)]
        vase_geom = np.array([g.startswith("vase") for g in geoms])
        agent_geom = np.array([g in task.agent.body_info.geom_names for g in geoms])
    return _Sim(task=task, model=model, data=task.data, rng=task.random_generator.random_generator,
                bodies=np.array([model.body(b).id for b in names], np.int64),
                raw=np.concatenate(raw) if raw else np.zeros(0, np.int64), quats=quats,
                vase_geom=vase_geom, agent_geom=agent_geom)


def _vase_costs(sims, vases) -> dict[str, np.ndarray]:
    """``Vases.cal_cost``: an agent geom touching a vase; a vase moving at ≥ the velocity threshold
    (its speed from ``get_body_xvelp``: the body's Jacobian times qvel, as the stock code has it)."""
    from safety_gymnasium.utils.task_utils import get_body_xvelp

    contact, moving = np.zeros(len(sims)), np.zeros(len(sims))
    for j, s in enumerate(sims):
        if vases.contact_cost:
            c, k = s.data.contact, s.data.ncon
            g1, g2 = np.asarray(c.geom1[:k]), np.asarray(c.geom2[:k])
            contact[j] = float(((s.vase_geom[g1] | s.vase_geom[g2]) & (s.agent_geom[g1] | s.agent_geom[g2])).any())
        if vases.velocity_cost:
            moving[j] = float(any(np.sqrt(np.sum(np.square(get_body_xvelp(s.model, s.data, f"vase{v}"))))
                                  >= vases.velocity_threshold for v in range(vases.num)))
    out = {"cost_vases_contact": contact}
    if vases.velocity_cost:
        out["cost_vases_velocity"] = moving
    return out


def _quat2mat(quat: np.ndarray) -> np.ndarray:
    """safety_gymnasium's ``quat2mat`` (``mju_quat2Mat``), flattened."""
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.array(quat, dtype="float64"))
    return m


def _resampling_error():
    from safety_gymnasium.utils.common_utils import ResamplingError

    return ResamplingError


def make_batched(env_id: str, num_envs: int, **kwargs) -> gym.vector.VectorEnv:
    """The vector env of ``num_envs`` envs of ``env_id`` on the batched backend."""
    return BatchedNavigationEnv(env_id, num_envs, **kwargs)
