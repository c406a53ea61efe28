"""A user's own env as a task: built by a ``"module:function"`` factory or made from a registered
gymnasium id, with its per-step cost read from a named ``info`` key.

The sweep file declares it (``task: {factory: "mypkg.envs:make", cost_limit: 10}``,
sweeps/sweep_file.py ``UserEnv``); :func:`user_task` turns that into a :class:`TaskSpec` after
building the env once and stepping it (:func:`check_env`), so an env the algorithms cannot train
on is refused before Ray starts. The spec travels to every process that needs it (Tune trials,
env runners, checkpoints: ``TaskSpec.definition``), where :func:`register_definition` adds it.
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym
import numpy as np

from lac_rllib.errors import announce, cut, excerpt
from lac_rllib.tasks.constraints import Constraint
from lac_rllib.tasks.registry import TaskSpec, register

FACTORY = "lac_rllib.tasks.user:make_env"


class CostFromInfo(gym.Wrapper):
    """The user's env with its step cost copied from ``info[cost_key]`` into ``info["cost"]`` (a
    float: where every algorithm reads it), observations as float32. An env that declares
    constraints and has no ``cost_key`` gets the sum of its constraints' keys there."""

    def __init__(self, env: gym.Env, cost_key: str, constraint_keys: tuple[str, ...] = ()):
        super().__init__(env)
        self.cost_key, self.constraint_keys = cost_key, tuple(constraint_keys)
        box = env.observation_space
        self.observation_space = gym.spaces.Box(box.low.astype(np.float32), box.high.astype(np.float32),
                                                dtype=np.float32)

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return np.asarray(obs, dtype=np.float32), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.cost_key not in info and self.constraint_keys and all(k in info for k in self.constraint_keys):
            info = {**info, "cost": float(sum(float(info[k]) for k in self.constraint_keys))}
        elif self.cost_key not in info:
            raise KeyError(f"the env's step info has no {self.cost_key!r} (keys: {sorted(info)}); "
                           "a safe task reports its step cost there")
        info = {**info, "cost": float(info[self.cost_key])}
        return np.asarray(obs, dtype=np.float32), float(reward), bool(terminated), bool(truncated), info


_OWN_KEYS = ("factory", "gym_id", "cost_key", "constraint_keys", "module_path", "num_envs")


def _module_of(cfg: dict) -> str | None:
    """The module a factory (``mod:fn``) or a gymnasium id in ``mod:Env-v0`` form imports."""
    source = cfg.get("factory") or cfg.get("gym_id") or ""
    return source.split(":")[0] if ":" in source else None


def locate(module: str, search_dirs: list[str]) -> str | None:
    """The directory that holds ``module``'s top-level package, from the Python path, else from the
    first of ``search_dirs`` (the sweep file's folder, the working directory) holding it (then put
    on ``sys.path``). Trials import it from there (``module_path``: Ray's workers do not share the
    driver's path), on every node that mounts that folder. None: not found (the build says so)."""
    import importlib.util
    import os
    import sys

    top = module.split(".")[0]
    for folder in search_dirs:
        if os.path.exists(os.path.join(folder, top + ".py")) or os.path.isdir(os.path.join(folder, top)):
            if importlib.util.find_spec(top) is None:
                sys.path.append(folder)
            break
    spec = importlib.util.find_spec(top)
    if spec is None or not spec.origin or spec.origin in ("built-in", "frozen"):
        return None
    origin = os.path.dirname(spec.origin)  # .../top.py -> its folder; .../top/__init__.py -> top/
    return os.path.dirname(origin) if spec.submodule_search_locations else origin


def _inner(cfg: dict) -> gym.Env:
    import sys

    if cfg.get("module_path") and cfg["module_path"] not in sys.path:
        sys.path.append(cfg["module_path"])  # where the driver found the user's module
    kwargs = {k: v for k, v in cfg.items() if k not in _OWN_KEYS}
    if cfg.get("factory"):
        module, func = cfg["factory"].split(":")
        return getattr(importlib.import_module(module), func)(kwargs)
    return gym.make(cfg["gym_id"], **kwargs)


def make_env(env_config: dict | None = None) -> gym.Env:
    """Build the user's env (any process): the TaskSpec's kwargs name the factory or id and the cost key."""
    cfg = dict(env_config or {})
    return CostFromInfo(_inner(cfg), cfg.get("cost_key", "cost"), tuple(cfg.get("constraint_keys") or ()))


def check_env(env: gym.Env, cost_key: str, what: str, steps: int = 5,
              constraints: dict[str, str] | None = None) -> tuple[int, int]:
    """(obs_dim, act_dim) of an env the algorithms can train on, or a ValueError saying why not:
    not a gymnasium env, spaces that are not flat Boxes, a reset or step that raises or returns
    something else than gymnasium's tuples, or a step whose info holds no cost (``cost_key``, or
    where it declares ``constraints`` (name → info key), each of their keys)."""
    if not isinstance(env, gym.Env):
        raise ValueError(f"{what}: the factory returned {excerpt(env)} (a {type(env).__name__}); "
                         "accepted: a gymnasium.Env")
    for kind, space in (("observation", env.observation_space), ("action", env.action_space)):
        if not (isinstance(space, gym.spaces.Box) and len(space.shape) == 1):
            raise ValueError(f"{what}: its {kind} space is {excerpt(space, 120)}; accepted: a flat Box "
                             "(1-D gymnasium.spaces.Box)")
    _returns(what, "reset(seed=0)", _call(what, "reset(seed=0)", env.reset, seed=0), 2, "(obs, info)")
    env.action_space.seed(0)
    for _ in range(steps):
        out = _call(what, "step(action)", env.step, env.action_space.sample())
        _, _, terminated, truncated, info = _returns(what, "step(action)", out, 5,
                                                     "(obs, reward, terminated, truncated, info)")
        keys = sorted(map(str, info)) if isinstance(info, dict) else f"not a dict: {excerpt(info)}"
        for name, key in (constraints or {}).items():
            if not isinstance(info, dict) or key not in info:
                raise ValueError(f"{what}: its step info has no {key!r}, the key of constraint {name!r} (keys: "
                                 f"{keys or 'none'}); accepted: constraints naming keys its step info has")
            _call(what, f"float(info[{key!r}])", float, info[key])
        # With constraints and no cost_key, info["cost"] is the sum of their keys (CostFromInfo).
        if not (constraints and cost_key not in info):
            if not isinstance(info, dict) or cost_key not in info:
                raise ValueError(f"{what}: its step info has no {cost_key!r} (keys: {keys or 'none'}); accepted: "
                                 f"an env that reports the step's cost in info[{cost_key!r}] (or name the key: "
                                 "cost_key)")
            _call(what, f"float(info[{cost_key!r}])", float, info[cost_key])
        if terminated or truncated:
            _call(what, "reset()", env.reset)
    return int(env.observation_space.shape[0]), int(env.action_space.shape[0])


def _call(what: str, call: str, fn, *args, **kwargs):
    """``fn(*args)``, with anything the user's code raises as one ValueError naming the env and the call."""
    try:
        return fn(*args, **kwargs)
    except Exception as e:  # the user's own code: any exception, said in one line
        raise ValueError(f"{what}: {call} raised {type(e).__name__}: {cut(str(e))}") from None


def _returns(what: str, call: str, out, n: int, shape: str):
    if not (isinstance(out, tuple) and len(out) == n):
        raise ValueError(f"{what}: {call} returned {excerpt(out)}; accepted: gymnasium's {shape}")
    return out


def user_task(task_id: str, *, factory: str | None = None, gym_id: str | None = None, cost_limit: float,
              episode_cost_discount: float = 1.0, cost_key: str = "cost", preset: str = "mujoco",
              kwargs: dict | None = None, search_dirs: tuple[str, ...] = (),
              constraints: dict[str, str] | None = None) -> TaskSpec:
    """The TaskSpec of a user's env, after building it once and stepping it (``check_env``); registered.
    Its module is imported from the Python path, else from the first of ``search_dirs`` holding it.
    ``constraints`` (name → the info key of its step cost) are the constraints a run may set limits on."""
    source = factory or gym_id
    announce(f"building and stepping your env {source} (task {task_id})")
    env_kwargs = {"factory": factory, "gym_id": gym_id, "cost_key": cost_key, **(kwargs or {})}
    if constraints:
        env_kwargs["constraint_keys"] = list(constraints.values())
    module = _module_of(env_kwargs)
    if module:
        env_kwargs["module_path"] = locate(module, list(search_dirs))
    try:
        inner = _inner(env_kwargs)
    except Exception as e:  # an import error, a bad id, the user's own exception: say which env
        raise ValueError(f"task {source}: cannot be built ({type(e).__name__}: {cut(str(e))})") from None
    try:
        obs_dim, act_dim = check_env(inner, cost_key, f"task {source}", constraints=constraints)
    except ValueError:
        if isinstance(inner, gym.Env):
            try:
                inner.close()
            except Exception:  # noqa: S110 (the check's error is the one to report)
                pass
        raise
    limit = getattr(getattr(inner, "spec", None), "max_episode_steps", None)  # gymnasium's registered TimeLimit
    _call(f"task {source}", "close()", inner.close)
    return register(TaskSpec(
        id=task_id, factory=FACTORY, cost_limit=float(cost_limit), episode_cost_discount=float(episode_cost_discount),
        preset=preset, obs_dim=obs_dim, act_dim=act_dim, cost_source=f"info[{cost_key!r}] of {source}",
        kwargs=env_kwargs, **({"episode_steps": int(limit)} if limit else {}),
        constraints=tuple(Constraint(name, (key,)) for name, key in (constraints or {}).items()),
    ))


def definition(spec: TaskSpec) -> dict[str, Any]:
    """A user task's spec as plain data (it travels in trial configs and checkpoints)."""
    import dataclasses

    return dataclasses.asdict(spec)


def register_definition(spec: dict[str, Any]) -> TaskSpec:
    """Register a user task in this process from :func:`definition`'s data (no env is built).
    Keys a TaskSpec no longer has are dropped (``overrides``, before 0.3: a user task had none)."""
    import dataclasses

    known = {f.name for f in dataclasses.fields(TaskSpec)}
    return register(TaskSpec(**{k: v for k, v in spec.items() if k in known}))
