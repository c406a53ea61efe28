"""``lac/PointHazard-v0``: a tiny safe task in pure numpy (tests and the smallest budgets).

A point in the plane starts near (-1, 0) and must reach the goal at (1, 0) within 100 steps of
at most 0.1. A round hazard of radius 0.35 sits at the origin, right on the straight path: each
step inside it costs 1. Reward per step = progress towards the goal − 0.1 (so time matters), +1 on
reaching the goal.

Why it is a fair constrained test: the straight path takes ~20 steps and ~7 of them are in the
hazard (episode cost ≈ 7 > the limit 2), so an unconstrained agent violates the limit (LAC with
ν pinned at 0 ends at cost ≈ 11, return ≈ 0.7); the detour around the disc costs 0 and a few
steps (LAC with ν ends at cost 0, return ≈ 0.3). A random policy does not reach the goal
(return ≈ −10) and drifts into the hazard now and then.

``lac/PointTwoCosts-v0`` is the same task with two constraints (tests of several constraints): the
hazard disc (``info["cost_hazard"]``, as above) and a lane (``info["cost_lane"]`` = 1 on a step
that ends above the x axis, y > 0: a random policy pays ~50 an episode, one that keeps below the
axis 0, at little cost in return); ``info["cost"]`` is their sum. Which one binds is the limits'
choice.

Also ``lac/CostProbe-v0``: a diagnostic task whose cost is a known function of the step
(cost = 2·t + 1 at step t, the observation carries t), to check cost/row alignment.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from lac_rllib.tasks.constraints import Constraint
from lac_rllib.tasks.registry import TINY, TaskSpec, register

GOAL = (1.0, 0.0)
HAZARD_RADIUS = 0.35
GOAL_RADIUS = 0.1
MAX_SPEED = 0.1
STEP_PENALTY = 0.1
GOAL_BONUS = 1.0


class PointHazardEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(self, max_steps: int = 100, hazard_radius: float = HAZARD_RADIUS):
        self.max_steps = int(max_steps)
        self.hazard_radius = float(hazard_radius)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._x = self._y = 0.0
        self._t = 0

    def _obs(self) -> np.ndarray:
        x, y = self._x, self._y
        return np.array(
            [x, y, GOAL[0] - x, GOAL[1] - y, -x, -y, math.hypot(x, y) - self.hazard_radius],
            dtype=np.float32,
        )

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._x = -1.0 + float(self.np_random.uniform(-0.05, 0.05))
        self._y = float(self.np_random.uniform(-0.1, 0.1))
        self._t = 0
        return self._obs(), {"cost": 0.0}

    def step(self, action):
        ax = min(max(float(action[0]), -1.0), 1.0)
        ay = min(max(float(action[1]), -1.0), 1.0)
        d_before = math.hypot(GOAL[0] - self._x, GOAL[1] - self._y)
        self._x += MAX_SPEED * ax
        self._y += MAX_SPEED * ay
        self._t += 1
        d_after = math.hypot(GOAL[0] - self._x, GOAL[1] - self._y)
        reached = d_after < GOAL_RADIUS
        reward = (d_before - d_after) - STEP_PENALTY + (GOAL_BONUS if reached else 0.0)
        cost = 1.0 if math.hypot(self._x, self._y) < self.hazard_radius else 0.0
        truncated = (not reached) and self._t >= self.max_steps
        return self._obs(), reward, reached, truncated, {"cost": cost}


class PointTwoCostsEnv(PointHazardEnv):
    """PointHazard with a second cost, the lane: ``cost_hazard`` and ``cost_lane`` apart, ``cost`` their sum."""

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        lane = float(self._y > 0.0)
        info = {"cost_hazard": info["cost"], "cost_lane": lane, "cost": info["cost"] + lane}
        return obs, reward, terminated, truncated, info


class CostProbeEnv(gym.Env):
    """Cost of step t is 2t + 1, reward is −t; obs = [t]; episodes of ``length`` steps."""

    def __init__(self, length: int = 7):
        self.length = int(length)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(1,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self._t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._t = 0
        return np.array([0.0], np.float32), {"cost": 0.0}

    def step(self, action):
        t = self._t
        self._t += 1
        obs = np.array([float(self._t)], np.float32)
        return obs, -float(t), self._t >= self.length, False, {"cost": 2.0 * t + 1.0}


def make_point_hazard(env_config: dict) -> gym.Env:
    return PointHazardEnv(**{k: v for k, v in env_config.items() if k in ("max_steps", "hazard_radius")})


def make_point_two_costs(env_config: dict) -> gym.Env:
    return PointTwoCostsEnv(**{k: v for k, v in env_config.items() if k in ("max_steps", "hazard_radius")})


def make_cost_probe(env_config: dict) -> gym.Env:
    return CostProbeEnv(**{k: v for k, v in env_config.items() if k in ("length",)})


POINT_HAZARD = register(TaskSpec(
    id="lac/PointHazard-v0", factory=f"{__name__}:make_point_hazard", cost_limit=2.0,
    episode_cost_discount=1.0, preset=TINY, obs_dim=7, act_dim=2,
    cost_source='info["cost"] = 1 inside the hazard disc', episode_steps=100,
))
POINT_TWO_COSTS = register(TaskSpec(
    id="lac/PointTwoCosts-v0", factory=f"{__name__}:make_point_two_costs", cost_limit=20.0,
    episode_cost_discount=1.0, preset=TINY, obs_dim=7, act_dim=2,
    cost_source='info["cost"] = hazard + lane (lac/PointHazard-v0 plus 1 per step above the x axis)',
    episode_steps=100, constraints=(Constraint("hazard", ("cost_hazard",)), Constraint("lane", ("cost_lane",))),
))
COST_PROBE = register(TaskSpec(
    id="lac/CostProbe-v0", factory=f"{__name__}:make_cost_probe", cost_limit=1e9,
    episode_cost_discount=1.0, preset=TINY, obs_dim=1, act_dim=1,
    cost_source='info["cost"] = 2t + 1 (diagnostic)', episode_steps=7,
))
