"""FOCOPS-convention MuJoCo tasks (docs/spec.md §6, rows marked [F]) on gymnasium's MuJoCo envs.

Ids, sizes, limits (episode cost Ĵ_C = Σ_t 0.99^t c_t, i.e. ``episode_cost_discount=0.99``;
1000-step episodes; LAC preset ``"mujoco"``):

=============================  ==========================  ==========  =========
id                              env (gymnasium 1.2.2)       obs / act   limit b
=============================  ==========================  ==========  =========
``focops/AntVelocity-v0``       ``ant_v4.AntEnv``           27 / 8      103.115
``focops/SwimmerVelocity-v0``   ``swimmer_v4.SwimmerEnv``   8 / 2       24.516
``focops/HumanoidVelocity-v0``  ``humanoid_v4.HumanoidEnv`` 376 / 17    20.140
``focops/HumanoidCircle-v0``    HumanoidCircleEnv (v4)      378 / 17    50
=============================  ==========================  ==========  =========

**Why the v4 envs.** FOCOPS ran gym's ``Ant-v3``, ``Swimmer-v3``, ``Humanoid-v3`` (mujoco-py).
gymnasium's ``*_v4`` classes are the same models, rewards and observation layouts on the
``mujoco`` bindings, and they are what Safety-Gymnasium's velocity tasks subclass, so both cost
conventions share dynamics and reward. Sizes: ``AntEnv(use_contact_forces=False)`` (the v4
default) observes ``qpos[2:]`` + ``qvel`` = 27; Swimmer 8; ``Humanoid`` v4 observes 376
(qpos[2:], qvel, cinert, cvel, qfrc_actuator, cfrc_ext incl. the world body). ``Humanoid-v5``
drops the world-body rows (348) and no v5 flag restores 376, so v4 is the only gymnasium env
with the paper's 376. (``Ant-v5`` with ``include_cfrc_ext_in_observation=False`` is also 27, but
changes the reward: contact cost always on, healthy reward only while healthy.) The v4 classes
are constructed directly (not ``gym.make("Ant-v4")``) to avoid the "out of date" warning; the
reward is the v4 env's own, unchanged.

**Velocity cost.** c_t = √(vx² + vy²), the planar speed over the control step, computed by
finite differences from the simulator state before and after the step,
``(p_after − p_before) / dt`` with ``dt = timestep · frame_skip``, exactly what FOCOPS used (it
took ``info["x_velocity"], info["y_velocity"]`` of the v3 envs, which are computed that way):
p is the ``torso`` body position ``data.xpos`` for Ant, the root slide joints ``qpos[0:2]`` for
Swimmer and the centre of mass Σ mᵢ·xiposᵢ / Σ mᵢ for Humanoid. We compute it ourselves from
``data`` (it equals the v4 envs' ``info["x_velocity"]``/``["y_velocity"]``). ``data.xpos`` and
``xipos`` are read as ``mj_step`` leaves them (kinematics from the last evaluation inside the
step, not recomputed after the final integration), exactly as gym/gymnasium read them for
those info velocities.

**HumanoidCircle** (FOCOPS' ``mujoco-circle`` ``HumanoidCircle``): Humanoid v4 with the full
qpos observed (``exclude_current_positions_from_observation=False``: x, y of the root are the
first two entries, 376 + 2 = 378), reward (−vx·y + vy·x) / (1 + |‖(x, y)‖ − 10|) with no alive,
control or contact terms, where (x, y) is the centre of mass after the step and (vx, vy) its
finite-difference velocity over the step; cost 1[|x| > 2.5] on the same x; reset: the usual
±0.01 uniform noise on qpos/qvel, then the root placed at 10·(cos θ, sin θ), θ ~ U[0, 2π) from the
env's seeded RNG; actions clipped to the action space Box(−0.4, 0.4) (the humanoid's native
control range). Healthy termination is kept as in FOCOPS' env (terminate when the torso height
qpos[2] leaves (1.0, 2.0)): without an alive bonus, early termination only forfeits the
(signed) circling reward, which matches the published setup.

Every env reports the per-step cost in ``info["cost"]`` (float), returns float32 observations
and is wrapped in a 1000-step ``TimeLimit``. Importing this module does not import mujoco.

env_config keys understood by :func:`make_env`: ``task`` (set by the task's kwargs),
``max_episode_steps`` (default 1000), ``render_mode``. Other keys are ignored.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable

import gymnasium as gym
import numpy as np

from lac_rllib.tasks.registry import MUJOCO, TaskSpec, register

FACTORY = "lac_rllib.tasks.mujoco_tasks:make_env"
MAX_EPISODE_STEPS = 1000
COST_DISCOUNT = 0.99

CIRCLE_RADIUS = 10.0
CIRCLE_X_LIMIT = 2.5


# ----------------------------------------------------------------- planar positions


def torso_xy(model: Any, data: Any) -> np.ndarray:
    """Ant: planar position of the ``torso`` body frame (what ``get_body_com("torso")`` reads)."""
    return data.body("torso").xpos[:2].copy()


def root_slide_xy(model: Any, data: Any) -> np.ndarray:
    """Swimmer: the root's x and y slide joints."""
    return data.qpos[0:2].copy()


def mass_center_xy(model: Any, data: Any) -> np.ndarray:
    """Humanoid: planar centre of mass Σ mᵢ·xiposᵢ / Σ mᵢ."""
    return (model.body_mass @ data.xipos / model.body_mass.sum())[:2].copy()


# (env class "module:Class", constructor kwargs, planar position used for the cost)
_VELOCITY_TASKS: dict[str, tuple[str, dict, Callable[[Any, Any], np.ndarray]]] = {
    "AntVelocity": (
        "gymnasium.envs.mujoco.ant_v4:AntEnv",
        {"use_contact_forces": False},
        torso_xy,
    ),
    "SwimmerVelocity": ("gymnasium.envs.mujoco.swimmer_v4:SwimmerEnv", {}, root_slide_xy),
    "HumanoidVelocity": ("gymnasium.envs.mujoco.humanoid_v4:HumanoidEnv", {}, mass_center_xy),
}


class Float32Obs(gym.ObservationWrapper):
    """Cast a flat Box observation to float32."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        space = env.observation_space
        self.observation_space = gym.spaces.Box(
            space.low.astype(np.float32), space.high.astype(np.float32), dtype=np.float32
        )

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return np.asarray(observation, dtype=np.float32)


class PlanarSpeedCost(gym.Wrapper):
    """``info["cost"]`` = ‖Δp‖ / dt over the step, p = ``position(model, data)`` (planar)."""

    def __init__(self, env: gym.Env, position: Callable[[Any, Any], np.ndarray]) -> None:
        super().__init__(env)
        self._position = position

    def step(self, action: Any):
        sim = self.env.unwrapped
        before = self._position(sim.model, sim.data)
        obs, reward, terminated, truncated, info = self.env.step(action)
        after = self._position(sim.model, sim.data)
        vx, vy = (after - before) / sim.dt
        info = dict(info)
        info["cost"] = float(np.sqrt(vx * vx + vy * vy))
        return obs, reward, terminated, truncated, info


# ----------------------------------------------------------------- HumanoidCircle


def _build_humanoid_circle_class() -> type:
    from gymnasium.envs.mujoco.humanoid_v4 import HumanoidEnv
    from gymnasium.utils import EzPickle

    class HumanoidCircleEnv(HumanoidEnv):
        """FOCOPS' HumanoidCircle on gymnasium's Humanoid v4 (see the module docstring)."""

        def __init__(self, **kwargs: Any) -> None:
            kwargs.setdefault("exclude_current_positions_from_observation", False)
            super().__init__(**kwargs)
            EzPickle.__init__(self, **kwargs)  # re-created from our kwargs when unpickled

        def step(self, action: Any):
            action = np.clip(
                np.asarray(action, dtype=np.float64), self.action_space.low, self.action_space.high
            )
            before = mass_center_xy(self.model, self.data)
            self.do_simulation(action, self.frame_skip)
            after = mass_center_xy(self.model, self.data)
            vx, vy = (after - before) / self.dt
            x, y = after
            dist = float(np.sqrt(x * x + y * y))
            reward = float((-vx * y + vy * x) / (1.0 + abs(dist - CIRCLE_RADIUS)))
            cost = float(abs(x) > CIRCLE_X_LIMIT)
            observation = self._get_obs()
            terminated = bool(self.terminated)
            info = {
                "x_position": float(x),
                "y_position": float(y),
                "distance_from_origin": dist,
                "x_velocity": float(vx),
                "y_velocity": float(vy),
                "cost": cost,
            }
            if self.render_mode == "human":
                self.render()
            return observation, reward, terminated, False, info

        def reset_model(self) -> np.ndarray:
            low, high = -self._reset_noise_scale, self._reset_noise_scale
            qpos = self.init_qpos + self.np_random.uniform(low=low, high=high, size=self.model.nq)
            qvel = self.init_qvel + self.np_random.uniform(low=low, high=high, size=self.model.nv)
            angle = self.np_random.uniform(0.0, 2.0 * np.pi)
            qpos[0:2] = CIRCLE_RADIUS * np.cos(angle), CIRCLE_RADIUS * np.sin(angle)
            self.set_state(qpos, qvel)
            return self._get_obs()

    HumanoidCircleEnv.__module__ = __name__
    HumanoidCircleEnv.__qualname__ = "HumanoidCircleEnv"
    return HumanoidCircleEnv


def __getattr__(name: str) -> Any:
    # ``HumanoidCircleEnv`` is built on first access (it subclasses a mujoco env, and importing
    # this module must stay cheap); module-level lookup keeps it picklable.
    if name == "HumanoidCircleEnv":
        cls = _build_humanoid_circle_class()
        globals()[name] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ----------------------------------------------------------------- factory


def make_env(env_config: dict | None = None) -> gym.Env:
    """Build one env of a FOCOPS-convention task (works in any process)."""
    cfg = dict(env_config or {})
    task = cfg.get("task")
    kwargs: dict[str, Any] = {}
    if cfg.get("render_mode") is not None:
        kwargs["render_mode"] = cfg["render_mode"]
    if task == "HumanoidCircle":
        env: gym.Env = __getattr__("HumanoidCircleEnv")(**kwargs)
    elif task in _VELOCITY_TASKS:
        entry, env_kwargs, position = _VELOCITY_TASKS[task]
        module, cls_name = entry.split(":")
        env_cls = getattr(importlib.import_module(module), cls_name)
        env = PlanarSpeedCost(env_cls(**env_kwargs, **kwargs), position)
    else:
        known = sorted([*_VELOCITY_TASKS, "HumanoidCircle"])
        raise ValueError(f"unknown FOCOPS task {task!r}; known: {known}")
    env = Float32Obs(env)
    return gym.wrappers.TimeLimit(env, int(cfg.get("max_episode_steps", MAX_EPISODE_STEPS)))


def _task(name: str, obs_dim: int, act_dim: int, limit: float, cost_source: str) -> TaskSpec:
    return TaskSpec(
        id=f"focops/{name}-v0",
        factory=FACTORY,
        cost_limit=limit,
        episode_cost_discount=COST_DISCOUNT,
        preset=MUJOCO,
        obs_dim=obs_dim,
        act_dim=act_dim,
        cost_source=cost_source,
        kwargs={"task": name},
    )


TASKS: tuple[TaskSpec, ...] = (
    _task("AntVelocity", 27, 8, 103.115, "planar speed of the torso (finite difference)"),
    _task("SwimmerVelocity", 8, 2, 24.516, "planar speed of the root (finite difference)"),
    _task("HumanoidVelocity", 376, 17, 20.140, "planar speed of the centre of mass"),
    _task("HumanoidCircle", 378, 17, 50.0, "1[|x_com| > 2.5]"),
)

for _t in TASKS:
    register(_t)
