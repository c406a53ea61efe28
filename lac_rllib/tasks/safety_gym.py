"""Safety-Gymnasium tasks (docs/spec.md §6; every id and its sizes: docs/tasks.md).

Registered: every Safety-Gymnasium 1.0 navigation task with flat observations (robots Point,
Car, Doggo, Racecar, Ant × Goal/Button/Push/Circle levels 0-2 and Run0: 65 ids) and the six
velocity v1 tasks (Ant, HalfCheetah, Hopper, Humanoid, Swimmer, Walker2d). The Vision variants
(``...Vision-v0``: dict observations, not flat Boxes) and the keyboard ``...Debug-v0`` ids are
not registered; neither are the velocity v0 tasks (OmniSafe reports v1).

Every env built here is safety_gymnasium's own env (6-tuple ``step``) made through
``safety_gymnasium``'s ``make`` with the spec safety_gymnasium registered (so its usual wrappers
apply: passive env checker, order enforcing and a ``SafeTimeLimit`` of the task's episode length:
1000 steps, 500 for Circle and Run as safety_gymnasium registers them), then wrapped by
:class:`SafetyToGymnasium` into the standard gymnasium 5-tuple form with the per-step cost in
``info["cost"]`` (a float), float32 observations and a float32 action space.

Costs are safety_gymnasium's, unchanged:

* navigation: ``info["cost"]`` ∈ {0, 1} (an indicator of any violation: the sources per task
  and level are in :data:`NAV_COSTS`; Goal0/Button0/Push0/Circle0 have none: cost always 0),
  episode cost = plain sum, limit 25, LAC preset ``"safety_gym"``;
* velocity v1 (the OmniSafe/Safety-Gymnasium convention): indicator cost
  1[speed > threshold] (Ant: torso, Humanoid: centre of mass) or 1[vx > threshold] (the planar
  ones), thresholds in :data:`VELOCITY`, summed, limit 25, LAC preset ``"mujoco"``. The
  underlying envs are gymnasium's ``*_v4`` MuJoCo envs.

The ids are the same as safety_gymnasium's. Our registrations win in gymnasium's registry
(``gym.make("SafetyPointGoal1-v0")`` gives the 5-tuple env built here);
``safety_gym_compat.apply()`` keeps safety_gymnasium's own specs for its ``make``.

Importing this module is cheap: mujoco and safety_gymnasium are imported by the factory only
(hence the sizes below are a measured table, not read from the envs;
tests/tasks/test_safety_gym.py checks them against the envs).

env_config keys understood by :func:`make_env`: ``env_id`` (set by the task's kwargs),
``max_episode_steps`` (default: the task's, :func:`episode_steps`), ``render_mode`` (default
None), ``light_resets`` (default True: navigation resets skip the render-only skybox when there
is no render_mode, lac_rllib.tasks.light_resets), ``robot_variant`` (a Point task's robot:
lac_rllib/tasks/point_robot.py), and with ``num_envs`` (RLlib's vector entry point) ``env_backend``
(:func:`make_batched`, or gymnasium's SyncVectorEnv of stock envs). Other keys are ignored.
"""

from __future__ import annotations

import contextlib
import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from lac_rllib.tasks import light_resets, point_robot
from lac_rllib.tasks.constraints import Constraint
from lac_rllib.tasks.registry import MUJOCO, SAFETY_GYM, TaskSpec, register

FACTORY = "lac_rllib.tasks.safety_gym:make_env"
#: Episode length of every task but those in :data:`NAV_EPISODE_STEPS`.
MAX_EPISODE_STEPS = 1000


class SafetyToGymnasium(gym.Wrapper):
    """safety_gymnasium 6-tuple env → gymnasium 5-tuple env with ``info["cost"]`` (float).

    Observations are cast to float32 (space: float32 Box with the same bounds); actions are
    accepted in a float32 Box and handed to the inner env in its own dtype.
    """

    def __init__(self, env: gym.Env, light_resets: bool = False) -> None:
        super().__init__(env)
        # Navigation resets without the render-only skybox (lac_rllib.tasks.light_resets).
        self._light_resets = light_resets
        obs_space, act_space = env.observation_space, env.action_space
        if not (isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1):
            raise TypeError(f"expected a flat Box observation space, got {obs_space}")
        self.observation_space = gym.spaces.Box(
            obs_space.low.astype(np.float32), obs_space.high.astype(np.float32), dtype=np.float32
        )
        self.action_space = gym.spaces.Box(
            act_space.low.astype(np.float32), act_space.high.astype(np.float32), dtype=np.float32
        )
        self._inner_action_dtype = act_space.dtype

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        with light_resets.light() if self._light_resets else contextlib.nullcontext():
            obs, info = self.env.reset(seed=seed, options=options)
        return np.asarray(obs, dtype=np.float32), info

    def step(self, action: Any):
        action = np.asarray(action, dtype=self._inner_action_dtype)
        obs, reward, cost, terminated, truncated, info = self.env.step(action)
        info = dict(info)
        info["cost"] = float(cost)
        return (
            np.asarray(obs, dtype=np.float32),
            float(reward),
            bool(terminated),
            bool(truncated),
            info,
        )


def make_env(env_config: dict | None = None) -> gym.Env | gym.vector.VectorEnv:
    """Build one env of a Safety-Gymnasium task (any process; applies the compat patches). Given
    ``num_envs`` (RLlib's vector entry point), a vector env of that many: :func:`make_batched` where
    the id has a batched backend and ``env_backend`` is "batched", else gymnasium's SyncVectorEnv."""
    from lac_rllib.tasks import safety_gym_compat

    cfg = dict(env_config or {})
    env_id = cfg.get("env_id")
    if env_id not in _SAFETY_IDS:
        raise ValueError(f"unknown Safety-Gymnasium task {env_id!r}; known: {sorted(_SAFETY_IDS)}")
    if "num_envs" in cfg:
        num_envs = int(cfg.pop("num_envs"))
        if cfg.get("env_backend", "batched") == "batched" and env_id in _NAV_IDS and supports(*_NAV_IDS[env_id]):
            return make_batched(env_id, num_envs, **{k: v for k, v in cfg.items() if k != "env_id"})
        return gym.vector.SyncVectorEnv([lambda: make_env(cfg) for _ in range(num_envs)])
    safety_gym_compat.apply()
    light_resets.install()
    from safety_gymnasium.utils.registration import make as safety_make

    kwargs = {}
    if cfg.get("render_mode") is not None:
        kwargs["render_mode"] = cfg["render_mode"]
    with warnings.catch_warnings():
        # safety_gymnasium builds float64 Boxes from float32 bounds; gymnasium's bound check
        # then warns "overflow encountered in cast" (harmless: the bounds are ±inf or ±1).
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        inner = safety_make(
            safety_gym_compat.safety_spec(env_id),
            max_episode_steps=int(cfg.get("max_episode_steps", episode_steps(env_id))),
            **kwargs,
        )
        light = bool(cfg.get("light_resets", True)) and cfg.get("render_mode") is None
        env = SafetyToGymnasium(inner, light_resets=light)
    variant = cfg.get("robot_variant", "safety_gymnasium")
    if variant != "safety_gymnasium" and (env_id not in _NAV_IDS or _NAV_IDS[env_id][0] != "Point"):
        raise ValueError(f"robot_variant={variant!r} on {env_id}: only the Point tasks have another robot; "
                         "accepted here: safety_gymnasium")
    point_robot.apply(env, variant)
    return env


def make_batched(env_id: str, num_envs: int, max_episode_steps: int | None = None,
                 **env_config) -> gym.vector.VectorEnv:
    """``num_envs`` envs of ``env_id`` stepped as one on the batched backend
    (lac_rllib/tasks/batched_navigation.py): stock envs (each :func:`make_env` of ``env_config``)
    that it steps, equal step for step."""
    from lac_rllib.tasks.batched_navigation import BatchedNavigationEnv

    if env_id not in _NAV_IDS or not supports(*_NAV_IDS[env_id]):
        raise ValueError(f"{env_id!r} has no batched backend; accepted: the {', '.join(BATCHED_FAMILIES)} tasks "
                         f"of {', '.join(BATCHED_ROBOTS)}, levels 0-2 (the others run on env_backend: stock)")
    cfg = {**env_config, "env_id": env_id}
    cfg.pop("env_backend", None)
    if max_episode_steps is not None:
        cfg["max_episode_steps"] = int(max_episode_steps)
    horizon = int(max_episode_steps or episode_steps(env_id))
    return BatchedNavigationEnv([make_env(cfg) for _ in range(int(num_envs))], _family(_NAV_IDS[env_id][1]), horizon)


# --------------------------------------------------------------------------- the tasks
#
# Cost limit b = 25 and a plain sum (cost_gamma 1) for every task: OmniSafe's convention for the
# Safety-Gymnasium tasks, which its benchmarks of these tasks report against (e.g.
# omnisafe/configs/on-policy/PPOLag.yaml: ``lagrange_cfgs.cost_limit: 25.0``, ``cost_gamma:
# 1.0``, one value for every task), and the limit docs/spec.md §6 gives the paper's tasks.

#: Navigation robots: act_dim (actions in [-1, 1] but Racecar's: wheel velocity ±20, steering ±0.785).
NAV_ROBOTS: dict[str, int] = {"Point": 2, "Car": 2, "Doggo": 12, "Racecar": 2, "Ant": 8}

#: obs_dim per navigation task (family + level) for the robots in NAV_ROBOTS' order, measured once
#: with safety_gymnasium 1.0.0 / mujoco 4.0.0. (They are the robot's own sensors, 12/24/56/12/40,
#: plus 16 lidar bins per observed object kind.)
NAV_OBS_DIMS: dict[str, tuple[int, int, int, int, int]] = {
    #          Point Car Doggo Racecar Ant
    "Goal0": (28, 40, 72, 28, 56),
    "Goal1": (60, 72, 104, 60, 88),
    "Goal2": (60, 72, 104, 60, 88),
    "Button0": (44, 56, 88, 44, 72),
    "Button1": (76, 88, 120, 76, 104),
    "Button2": (76, 88, 120, 76, 104),
    "Push0": (44, 56, 88, 44, 72),
    "Push1": (76, 88, 120, 76, 104),
    "Push2": (76, 88, 120, 76, 104),
    "Circle0": (28, 40, 72, 28, 56),
    "Circle1": (28, 40, 72, 28, 56),
    "Circle2": (28, 40, 72, 28, 56),
    "Run0": (12, 24, 56, 12, 40),
}

#: A raw env step's time per navigation task over ``SafetyPointGoal1-v0``'s (TaskSpec.step_cost, what
#: the sweep plan scales the env's share of a trial by), robots in NAV_ROBOTS' order: random actions,
#: 1,000 steps each, the reference timed before and after each task (``python benchmarks/envs.py
#: --step-costs``; AMD EPYC, 2026-12-03, beside a sweep: ±20%). Button, Goal2 and the Ant's and
#: Racecar's heavier bodies step 3-18x slower than PointGoal1; Point on level 0, Circle and Run 3x faster.
NAV_STEP_COST: dict[str, tuple[float, float, float, float, float]] = {
    #          Point Car Doggo Racecar Ant
    "Goal0": (0.37, 0.74, 1.9, 2.3, 2.4),
    "Goal1": (1.0, 1.3, 2.7, 3.4, 3.3),  # the reference: measured 0.89 against itself
    "Goal2": (3.8, 4.7, 6.0, 9.8, 9.1),
    "Button0": (0.84, 1.3, 2.4, 3.4, 2.7),
    "Button1": (3.3, 4.5, 4.5, 7.6, 16),
    "Button2": (4.6, 5.6, 5.5, 7.4, 18),
    "Push0": (1.0, 1.6, 2.8, 4.4, 4.4),
    "Push1": (1.3, 2.1, 2.8, 4.5, 5.1),
    "Push2": (2.0, 2.3, 3.8, 5.2, 5.5),
    "Circle0": (0.29, 0.89, 1.8, 2.8, 2.3),
    "Circle1": (0.36, 0.8, 1.8, 2.3, 2.7),
    "Circle2": (0.35, 0.79, 1.7, 2.3, 2.3),
    "Run0": (0.28, 0.63, 1.8, 2.5, 2.4),
}

#: What makes ``info["cost"]`` 1 (safety_gymnasium/tasks/safe_navigation/*/: the constrained
#: objects each level adds; level 0 has none, its cost is always 0, except Run0's walls).
NAV_COSTS: dict[str, str] = {
    "Goal0": "none: always 0",
    "Goal1": "hazards",  # its one vase is not constrained
    "Goal2": "hazards, vases touched or moving",
    "Button0": "none: always 0",  # buttons not constrained
    "Button1": "hazards, gremlins, wrong buttons",
    "Button2": "hazards, gremlins, wrong buttons",
    "Push0": "none: always 0",
    "Push1": "hazards",  # its one pillar is not constrained
    "Push2": "hazards, pillars",
    "Circle0": "none: always 0",
    "Circle1": "outside |x| <= 1.125",
    "Circle2": "outside |x|, |y| <= 1.125",
    "Run0": "outside |x| <= 0.5",
}

#: The constraints each navigation task declares (``TaskSpec.constraints``): its constrained
#: obstacles, each with the ``cost_*`` keys safety_gymnasium's ``calculate_cost`` writes for it
#: (assets/*: ``cal_cost``), an indicator each as ``info["cost"]`` is.
_HAZARDS = Constraint("hazards", ("cost_hazards",), indicator=True)
_BOUNDARY = Constraint("boundary", ("cost_out_of_boundary",), indicator=True)
NAV_CONSTRAINTS: dict[str, tuple[Constraint, ...]] = {
    "Goal1": (_HAZARDS,),
    "Goal2": (_HAZARDS, Constraint("vases", ("cost_vases_contact", "cost_vases_velocity"), indicator=True)),
    **{f"Button{level}": (_HAZARDS, Constraint("gremlins", ("cost_gremlins",), indicator=True),
                          Constraint("buttons", ("cost_buttons",), indicator=True)) for level in (1, 2)},
    "Push1": (_HAZARDS,),
    "Push2": (_HAZARDS, Constraint("pillars", ("cost_pillars",), indicator=True)),
    "Circle1": (_BOUNDARY,),
    "Circle2": (_BOUNDARY,),
    "Run0": (_BOUNDARY,),
}

#: safety_gymnasium registers Circle and Run with 500-step episodes (its task classes'
#: ``num_steps`` = 500 too); every other task runs 1000 steps.
NAV_EPISODE_STEPS: dict[str, int] = {"Circle": 500, "Run": 500}

#: Velocity v1 tasks: robot → (obs_dim, act_dim, indicator) with the thresholds of
#: safety_gymnasium/tasks/safe_velocity/*_v1.py (speed: planar, finite difference per step).
VELOCITY: dict[str, tuple[int, int, str]] = {
    "Ant": (27, 8, "1[sqrt(vx^2+vy^2) > 2.6222]"),  # torso
    "HalfCheetah": (17, 6, "1[vx > 3.2096]"),
    "Hopper": (11, 3, "1[vx > 0.7402]"),
    "Humanoid": (376, 17, "1[sqrt(vx^2+vy^2) > 1.4149]"),  # centre of mass
    "Swimmer": (8, 2, "1[vx > 0.2282]"),
    "Walker2d": (17, 6, "1[vx > 2.3415]"),
}


#: The navigation tasks with a batched backend (lac_rllib/tasks/batched_navigation.py): these robots
#: on these families, levels 0-2; every other id runs stock.
BATCHED_FAMILIES, BATCHED_ROBOTS = ("Goal", "Button", "Push"), ("Point", "Car")


def supports(robot: str, task: str) -> bool:
    """Whether ``Safety{robot}{task}-v0`` has a batched backend."""
    return robot in BATCHED_ROBOTS and _family(task) in BATCHED_FAMILIES and task[-1] in "012"


def _family(task: str) -> str:
    return task.rstrip("0123456789")


def nav_id(robot: str, task: str) -> str:
    """``("Point", "Goal1")`` → ``"SafetyPointGoal1-v0"``."""
    return f"Safety{robot}{task}-v0"


def velocity_id(robot: str) -> str:
    return f"Safety{robot}Velocity-v1"


def episode_steps(env_id: str) -> int:
    """The task's episode length (safety_gymnasium's ``max_episode_steps`` for the id)."""
    if env_id in _NAV_IDS:
        return NAV_EPISODE_STEPS.get(_family(_NAV_IDS[env_id][1]), MAX_EPISODE_STEPS)
    return MAX_EPISODE_STEPS


def _nav(robot: str, task: str) -> TaskSpec:
    env_id = nav_id(robot, task)
    return TaskSpec(
        id=env_id,
        factory=FACTORY,
        cost_limit=25.0,
        episode_cost_discount=1.0,
        preset=SAFETY_GYM,
        obs_dim=NAV_OBS_DIMS[task][list(NAV_ROBOTS).index(robot)],
        act_dim=NAV_ROBOTS[robot],
        cost_source=f'safety_gymnasium info["cost"] in {{0,1}} ({NAV_COSTS[task]}), summed',
        kwargs={"env_id": env_id},
        family=_family(task),
        step_cost=NAV_STEP_COST[task][list(NAV_ROBOTS).index(robot)],
        episode_steps=episode_steps(env_id),
        batched=supports(robot, task),
        robot=robot,
        constraints=NAV_CONSTRAINTS.get(task, ()),
    )


def _vel(robot: str) -> TaskSpec:
    env_id = velocity_id(robot)
    obs_dim, act_dim, indicator = VELOCITY[robot]
    return TaskSpec(
        id=env_id,
        factory=FACTORY,
        cost_limit=25.0,
        episode_cost_discount=1.0,
        preset=MUJOCO,
        obs_dim=obs_dim,
        act_dim=act_dim,
        cost_source=f"safety_gymnasium velocity v1 indicator {indicator}, summed",
        kwargs={"env_id": env_id},
        constraints=(Constraint("velocity", ("cost",)),),
    )


_NAV_IDS: dict[str, tuple[str, str]] = {
    nav_id(robot, task): (robot, task) for task in NAV_OBS_DIMS for robot in NAV_ROBOTS
}
TASKS: tuple[TaskSpec, ...] = (
    *(_nav(robot, task) for robot, task in _NAV_IDS.values()),
    *(_vel(robot) for robot in VELOCITY),
)
_SAFETY_IDS = frozenset(t.id for t in TASKS)

for _task in TASKS:
    register(_task)
