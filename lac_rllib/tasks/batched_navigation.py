"""N Safety-Gymnasium navigation envs stepped as one vector env, bit-identical to the stock ones.

A stock SafetyPointGoal1-v0 step spends ~20% of its time in MuJoCo and the rest in ~830 Python
calls of safety_gymnasium's task layer (../docs/speed.md). Here each step runs the physics of every
env (its ``mj_step`` calls and one ``mj_forward``) and then the task layer once for all N envs as
array operations: lidar and sensors (lac_rllib/tasks/navigation_layer.py), reward, the goal test
and the ``cost_*`` indicators (lac_rllib/tasks/navigation_rules.py), termination and truncation.

What stays safety_gymnasium's own code, run per env, because it is rare and its random stream
must be untouched: ``reset`` (layout sampling with its placement retries, the world rebuilt), the
goal's resampling when it is reached, and the Button tasks' timer tick. Each env is the stock env
of lac_rllib/tasks/safety_gym.py (compat shim, light resets: ``make_batched`` builds them); this
class only replaces their ``step``. The random draws a stock step makes (the frame-skip binomial)
are made on each env's own generator, in the same order, so every later layout is the same.

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

import mujoco
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from lac_rllib.tasks import navigation_layer as layer
from lac_rllib.tasks import navigation_rules as rules


@dataclasses.dataclass
class _Sim:
    """One env's handles into its current world (rebuilt at every reset)."""

    task: Any  #: safety_gymnasium's task object (its model and data change at each reset)
    model: Any
    data: Any
    rng: np.random.RandomState  #: the task's own generator
    bodies: np.ndarray  #: body ids read each step: the agent, then each group's objects in order
    raw: np.ndarray  #: sensordata addresses of the sensors read as they are, in the observation's order
    quats: list  #: sensordata addresses of the ball-joint quaternions (observed as rotation matrices)
    agent_geom: np.ndarray  #: per geom id: one of the agent's geoms
    prefixed: dict  #: geom-name prefix (rules.CONTACT_COSTS) → per geom id: its name starts so
    buttons: np.ndarray  #: geom id of button k
    mocaps: np.ndarray  #: the gremlins' mocap ids (moved before every physics step)
    vases: list  #: the vases' body names (their speed is a cost)
    # Views of the data's arrays, taken once (each attribute access of MjData makes a new view).
    ctrl: np.ndarray = None
    xpos: np.ndarray = None
    xmat: np.ndarray = None
    sensordata: np.ndarray = None
    mocap_pos: np.ndarray = None

    def __post_init__(self):
        d = self.data
        self.ctrl, self.xpos, self.xmat = d.ctrl, d.xpos, d.xmat
        self.sensordata, self.mocap_pos = d.sensordata, d.mocap_pos


@dataclasses.dataclass(frozen=True)
class _Layout:
    """Where each piece of the flat observation comes from (the same for every env of a task)."""

    groups: dict  #: body group → slice of ``_Sim.bodies`` (the agent is row 0)
    columns: list  #: per observation key in order: ("raw", raw slice) | ("quat", k) | ("lidar", group)
    at: list  #: per observation key: its slice of the flat observation
    seen: list  #: the lidar groups in the observation's order
    seen_slices: list  #: their slices of the bodies after the agent's


class BatchedNavigationEnv(VectorEnv):
    """``num_envs`` envs of one navigation task (``env_id``), stepped together."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, envs: list, family: str, horizon: int) -> None:
        """``envs``: stock envs of one task (lac_rllib/tasks/safety_gym.py ``make_env``; this class
        steps them, their own code resets them); ``family``: Goal, Button or Push; ``horizon``:
        the episode's steps before truncation. Built by ``safety_gym.make_batched``."""
        self.envs, self.num_envs = list(envs), len(envs)
        first = self.envs[0]
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._inner_dtype = first._inner_action_dtype
        task = first.unwrapped.task
        rules.check(task)
        self._task = task  # its configuration (sizes, rewards, lidar): the same in every env of the id
        self._rule = rules.RULES[family](task, self.num_envs)
        self._horizon = min(task.num_steps, int(horizon))
        self._layout = _layout(task)
        self._constrained, self._contacts = rules.constrained(task), rules.needs_contacts(task)
        self._sims: list[_Sim | None] = [None] * self.num_envs
        self._steps = np.zeros(self.num_envs, np.int64)
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
        task = self.envs[i].unwrapped.task
        self._sims[i] = _attach(task, self._layout)
        self._rule.reset(i, task)
        self._steps[i] = 0
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

    def _physics(self, sims, actions) -> None:
        """``Underlying.simulation_forward``: the control clipped to the actuators' range, the frame-skip
        draw on the env's own generator, the steps (each after the gremlins' mocaps move), one
        forward (the stock step's later forwards recompute the same fields from the same state)."""
        task = self._task
        span = task.model.actuator_ctrlrange
        ctrl = np.clip(actions, span[:, 0], span[:, 1])
        skip_n, skip_p = task.sim_conf.frameskip_binom_n, task.sim_conf.frameskip_binom_p
        step, forward = mujoco.mj_step, mujoco.mj_forward
        travel, size = (task.gremlins.travel, task.gremlins.size) if sims[0].mocaps.size else (0, 0)
        for j, sim in enumerate(sims):
            m, d = sim.model, sim.data
            sim.ctrl[:] = ctrl[j]
            frames = sim.rng.binomial(skip_n, skip_p)
            if not sim.mocaps.size:
                if frames:  # mj_step's nstep: the same steps, one call
                    step(m, d, frames)
            else:
                for _ in range(frames):  # Gremlins.move: every mocap to (sin t, cos t) · travel
                    phase = float(d.time)
                    sim.mocap_pos[sim.mocaps] = np.r_[np.array([np.sin(phase), np.cos(phase)]) * travel, [size]]
                    step(m, d)
            forward(m, d)

    def _frame(self, sims) -> rules.Frame:
        touching = [_touching(s) for s in sims] if self._contacts else [{}] * len(sims)
        # ``take``, not fancy indexing: the same copy, half the time on arrays this small.
        xpos = np.stack([s.xpos.take(s.bodies, axis=0) for s in sims])
        return rules.Frame(xpos=xpos, groups=self._layout.groups, touching=touching, tasks=[s.task for s in sims])

    def _step_live(self, live, actions, obs, rewards, terminated, truncated, infos) -> dict:
        sims = [self._sims[i] for i in live]
        self._physics(sims, actions)
        frame = self._frame(sims)
        # Builder.step's order: the reward, the costs, specific_step, then a met goal resampled.
        reward, achieved = self._rule.reward(frame, live)
        rewards[live] = layer.clip_reward(reward, self._task.reward_conf.reward_clip)
        costs = rules.costs(self._constrained, frame)
        for key, value in costs.items():  # the infos SyncVectorEnv would gather, key by key
            infos = self._add_column(infos, key, value, live)
        infos = self._add_column(infos, "cost", costs["cost_sum"], live)
        self._rule.step(frame)
        for j in np.flatnonzero(achieved):  # the goal resampled by safety_gymnasium's own code
            i, task = live[j], sims[j].task
            task.update_layout()
            try:
                task.update_world()
                self._rule.reset(i, task)
            except _resampling_error():
                terminated[i] = True
            infos = self._add_info(infos, {"goal_met": True}, i)
        xpos = np.stack([s.xpos.take(s.bodies, axis=0) for s in sims]) if achieved.any() else frame.xpos
        self._steps[live] += 1
        truncated[live] = self._steps[live] >= self._horizon
        obs[live] = self._observe(sims, xpos)
        return infos

    def _add_column(self, infos: dict, key: str, values: np.ndarray, rows: np.ndarray) -> dict:
        """``key``'s float values for the envs ``rows`` (NaN: the env has no such key), as
        ``_add_info`` per env would gather them."""
        has = ~np.isnan(values)
        if not has.any():
            return infos
        column = infos.get(key)
        if column is None:
            column, mask = np.zeros(self.num_envs), np.zeros(self.num_envs, np.bool_)
        else:
            mask = infos[f"_{key}"]
        column[rows[has]], mask[rows[has]] = values[has], True
        infos[key], infos[f"_{key}"] = column, mask
        return infos

    def _observe(self, sims, xpos) -> np.ndarray:
        """``BaseTask.obs`` flattened: the sensors, then each lidar, in the observation's order (the
        buttons' lidar reads 0 while their timer runs: ``ButtonLevel0.obs``), each block written
        into the float32 observation as the stock wrapper casts it."""
        c, layout = self._task.lidar_conf, self._layout
        obs = np.empty((len(sims), self.single_observation_space.shape[0]), self.observation_space.dtype)
        mat = np.stack([s.xmat[s.bodies[0]] for s in sims]).reshape(-1, 3, 3)
        raw = np.stack([s.sensordata.take(s.raw) for s in sims])
        # Every lidar at once: one egocentric transform and one pass over all the objects seen.
        ego = layer.ego_xy(xpos[:, 1:], xpos[:, 0], mat)
        lidars = dict(zip(layout.seen, layer.pseudo_lidars(ego, layout.seen_slices, c.num_bins, c.max_dist,
                                                           c.exp_gain, c.alias)))
        for (kind, what), at in zip(layout.columns, layout.at):
            if kind == "raw":
                obs[:, at] = raw[:, what]
            elif kind == "quat":
                obs[:, at] = np.stack([_quat2mat(s.sensordata[s.quats[what]]) for s in sims])
            else:
                lidar = lidars[what]
                if what == "buttons":
                    lidar[[s.task.buttons.timer != 0 for s in sims]] = 0.0
                obs[:, at] = lidar
        return obs

    def close_extras(self, **kwargs) -> None:
        for env in getattr(self, "envs", ()):  # none where __init__ refused the id
            env.close()


def _bodies(ob) -> list[str]:
    """The bodies of an obstacle, in the order its ``pos`` lists them."""
    if not hasattr(ob, "num"):
        return [ob.name]  # the goal, the push box
    if ob.name == "gremlins":
        return [f"gremlin{k}obj" for k in range(ob.num)]
    return [f"{ob.name[:-1]}{k}" for k in range(ob.num)]


def _layout(task) -> _Layout:
    groups, at = {}, 1
    for ob in task._obstacles:
        if ob.is_lidar_observed or ob.name in ("goal", "hazards", "push_box"):
            k = len(_bodies(ob))
            groups[ob.name] = slice(at, at + k)
            at += k
    columns, at, raw_at, obs_at = [], [], 0, 0
    quats = task.agent.sensor_info.ballquat_names
    for key, space in task.obs_info.obs_space_dict.items():
        dim = int(np.prod(space.shape))
        at.append(slice(obs_at, obs_at + dim))
        obs_at += dim
        if key.endswith("_lidar"):
            columns.append(("lidar", key[: -len("_lidar")]))
        elif key in quats:
            columns.append(("quat", quats.index(key)))
        else:
            columns.append(("raw", slice(raw_at, raw_at + dim)))
            raw_at += dim
    seen = [what for kind, what in columns if kind == "lidar"]
    return _Layout(groups=groups, columns=columns, at=at, seen=seen,
                   seen_slices=[slice(groups[g].start - 1, groups[g].stop - 1) for g in seen])


def _attach(task, layout: _Layout) -> _Sim:
    """Handles into ``task``'s current world, read in the stock observation's order."""
    model = task.model
    names = ["agent"] + [b for ob in task._obstacles if ob.name in layout.groups for b in _bodies(ob)]
    raw, quats = [], []
    info = task.agent.sensor_info
    for key in task.obs_info.obs_space_dict.keys():
        if key.endswith("_lidar"):
            continue
        sid = model.sensor(key).id
        adr = np.arange(model.sensor_adr[sid], model.sensor_adr[sid] + model.sensor_dim[sid])
        (quats.append(adr) if key in info.ballquat_names else raw.append(adr))
    geoms = [model.geom(g).name for g in range(model.ngeom)]
    needed = [rules.CONTACT_COSTS[ob.name] for ob in task._obstacles
              if ob.name in rules.CONTACT_COSTS and getattr(ob, "is_constrained", False)]
    prefixed = {p: np.array([g.startswith(p) for g in geoms]) for p in needed}
    buttons = getattr(task, "buttons", None)
    gremlins = getattr(task, "gremlins", None)
    vases = getattr(task, "vases", None)
    return _Sim(task=task, model=model, data=task.data, rng=task.random_generator.random_generator,
                bodies=np.array([model.body(b).id for b in names], np.int64),
                raw=np.concatenate(raw) if raw else np.zeros(0, np.int64), quats=quats,
                agent_geom=np.array([g in task.agent.body_info.geom_names for g in geoms]), prefixed=prefixed,
                buttons=np.array([model.geom(f"button{k}").id for k in range(buttons.num)] if buttons else [], int),
                mocaps=np.array([model.body_mocapid[model.body(f"gremlin{k}mocap").id] for k in range(gremlins.num)]
                                if gremlins else [], int),
                vases=[f"vase{k}" for k in range(vases.num)] if vases is not None and vases.is_constrained
                and vases.velocity_cost else [])


def _touching(s: _Sim) -> dict:
    """What an agent geom touches this step (``data.contact``, as the stock costs scan it): per
    geom-name prefix, the goal button, a wrong button; and whether a vase moves (speed ≥ threshold)."""
    out = {}
    k = s.data.ncon
    if not (s.prefixed or s.buttons.size or s.vases):
        return out  # the task decides nothing by contact (Goal0, Goal1, Push0, Push1)
    if k:
        c = s.data.contact
        g1, g2 = np.asarray(c.geom1[:k]), np.asarray(c.geom2[:k])
        agent = s.agent_geom[g1] | s.agent_geom[g2]
        for prefix, mask in s.prefixed.items():
            out[prefix] = bool(((mask[g1] | mask[g2]) & agent).any())
        if s.buttons.size:
            goal = s.buttons[s.task.buttons.goal_button]
            on_goal = (g1 == goal) | (g2 == goal)
            out["goal_button"] = bool((on_goal & agent).any())
            if "button" in s.prefixed:
                button = s.prefixed["button"][g1] | s.prefixed["button"][g2]
                out["wrong_button"] = bool((button & agent & ~on_goal).any())
    else:
        out = dict.fromkeys((*s.prefixed, "goal_button", "wrong_button"), False)
    if s.vases:
        from safety_gymnasium.utils.task_utils import get_body_xvelp

        threshold = s.task.vases.velocity_threshold
        out["vase_moving"] = any(np.sqrt(np.sum(np.square(get_body_xvelp(s.model, s.data, v)))) >= threshold
                                 for v in s.vases)
    return out


def _quat2mat(quat: np.ndarray) -> np.ndarray:
    """safety_gymnasium's ``quat2mat`` (``mju_quat2Mat``), flattened."""
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.array(quat, dtype="float64"))
    return m


def _resampling_error():
    from safety_gymnasium.utils.common_utils import ResamplingError

    return ResamplingError
