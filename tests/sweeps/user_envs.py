"""Envs a user writes (not part of the package): what the sweep's user-env path is tested with.

``make_safe``: a point on a line, pushed by its action toward 0 (reward −|x|); the step's cost
is ``info["violation"]`` = 1 past x > 0.5, where it starts half of the time. 50-step episodes.
"""

import gymnasium as gym
import numpy as np


class _Line(gym.Env):
    def __init__(self, cost: bool = True, dict_obs: bool = False, start: float = 1.0):
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        box = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
        self.observation_space = gym.spaces.Dict({"x": box}) if dict_obs else box
        self.cost, self.dict_obs, self.start = cost, dict_obs, start
        self.x, self.t = 0.0, 0

    def _obs(self):
        obs = np.array([self.x, self.t / 50.0])
        return {"x": obs} if self.dict_obs else obs

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(-self.start, self.start)), 0
        return self._obs(), {}

    def step(self, action):
        self.x = float(np.clip(self.x + 0.1 * float(np.asarray(action).reshape(-1)[0]), -2, 2))
        self.t += 1
        info = {"violation": float(self.x > 0.5)} if self.cost else {}
        return self._obs(), -abs(self.x), False, self.t >= 50, info


def make_safe(config):
    return _Line(start=float(config.get("start", 1.0)))


def make_costless(config):
    return _Line(cost=False)


def make_dict_obs(config):
    return _Line(dict_obs=True)


def make_int(config):
    """A factory that returns no env at all."""
    return 42


class _Raises(_Line):
    def __init__(self, where: str):
        super().__init__()
        self.where = where

    def reset(self, *, seed=None, options=None):
        if self.where == "reset":
            raise RuntimeError("the simulator could not load its scene")
        return super().reset(seed=seed, options=options)

    def step(self, action):
        if self.where == "step":
            raise RuntimeError("physics diverged at step 1")
        return super().step(action)

    def close(self):
        if self.where == "close":
            raise OSError("the viewer was already gone")


def make_step_raises(config):
    return _Raises("step")


def make_reset_raises(config):
    return _Raises("reset")


def make_close_raises(config):
    return _Raises("close")
