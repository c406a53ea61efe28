"""Safety-Gymnasium tasks (docs/spec.md §6): navigation (Point/Car × Goal1/Button1) and velocity v1.

Every env built here is safety_gymnasium's own env (6-tuple ``step``) made through
``safety_gymnasium``'s ``make`` with the spec safety_gymnasium registered (so its usual wrappers
apply: passive env checker, order enforcing and a 1000-step ``SafeTimeLimit``), then wrapped by
:class:`SafetyToGymnasium` into the standard gymnasium 5-tuple form with the per-step cost in
``info["cost"]`` (a float), float32 observations and a float32 action space.

Costs are safety_gymnasium's, unchanged:

* navigation: ``info["cost"]`` ∈ {0, 1} (Goal1: hazards; Button1: hazards, gremlins, wrong
  buttons), episode cost = plain sum, limit 25, LAC preset ``"safety_gym"``;
* velocity v1 (the OmniSafe/Safety-Gymnasium convention): indicator cost
  1[speed > 2.6222] (Ant), 1[vx > 0.2282] (Swimmer), 1[speed > 1.4149] (Humanoid), summed,
  limit 25, LAC preset ``"mujoco"``. The underlying envs are gymnasium's ``*_v4`` MuJoCo envs.

The ids are the same as safety_gymnasium's. Our registrations win in gymnasium's registry
(``gym.make("SafetyPointGoal1-v0")`` gives the 5-tuple env built here);
``safety_gym_compat.apply()`` keeps safety_gymnasium's own specs for its ``make``.

Importing this module is cheap: mujoco and safety_gymnasium are imported by the factory only.

env_config keys understood by :func:`make_env`: ``env_id`` (set by the task's kwargs),
``max_episode_steps`` (default 1000), ``render_mode`` (default None), ``light_resets`` (default
True: navigation resets skip the render-only skybox when there is no render_mode,
lac_rllib.tasks.light_resets). Other keys (e.g. RLlib's ``num_envs``) are ignored.
"""

from __future__ import annotations

import contextlib
import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from lac_rllib.tasks import light_resets
from lac_rllib.tasks.registry import MUJOCO, SAFETY_GYM, TaskSpec, register

FACTORY = "lac_rllib.tasks.safety_gym:make_env"
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


def make_env(env_config: dict | None = None) -> gym.Env:
    """Build one env of a Safety-Gymnasium task (any process; applies the compat patches)."""
    from lac_rllib.tasks import safety_gym_compat

    cfg = dict(env_config or {})
    env_id = cfg.get("env_id")
    if env_id not in _SAFETY_IDS:
        raise ValueError(f"unknown Safety-Gymnasium task {env_id!r}; known: {sorted(_SAFETY_IDS)}")
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
            max_episode_steps=int(cfg.get("max_episode_steps", MAX_EPISODE_STEPS)),
            **kwargs,
        )
        light = bool(cfg.get("light_resets", True)) and cfg.get("render_mode") is None
        return SafetyToGymnasium(inner, light_resets=light)


def _nav(env_id: str, obs_dim: int, hazards: str, overrides: dict | None = None) -> TaskSpec:
    return TaskSpec(
        id=env_id,
        factory=FACTORY,
        cost_limit=25.0,
        episode_cost_discount=1.0,
        preset=SAFETY_GYM,
        obs_dim=obs_dim,
        act_dim=2,
        cost_source=f'safety_gymnasium info["cost"] in {{0,1}} ({hazards}), summed',
        kwargs={"env_id": env_id},
        overrides=overrides or {},
    )


def _vel(env_id: str, obs_dim: int, act_dim: int, indicator: str) -> TaskSpec:
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
    )


TASKS: tuple[TaskSpec, ...] = (
    _nav("SafetyPointGoal1-v0", 60, "hazards"),
    _nav("SafetyCarGoal1-v0", 72, "hazards"),
    # Table 5: the Button tasks run T = 50 Langevin steps.
    _nav("SafetyPointButton1-v0", 76, "hazards, gremlins, wrong buttons", {"langevin_steps": 50}),
    _nav("SafetyCarButton1-v0", 88, "hazards, gremlins, wrong buttons", {"langevin_steps": 50}),
    _vel("SafetyAntVelocity-v1", 27, 8, "1[sqrt(vx^2+vy^2) > 2.6222]"),
    _vel("SafetySwimmerVelocity-v1", 8, 2, "1[vx > 0.2282]"),
    _vel("SafetyHumanoidVelocity-v1", 376, 17, "1[sqrt(vx^2+vy^2) > 1.4149]"),
)
_SAFETY_IDS = frozenset(t.id for t in TASKS)

for _task in TASKS:
    register(_task)
