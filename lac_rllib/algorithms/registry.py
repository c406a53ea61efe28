"""The algorithms a run or a trial can name (``algo``), declared once: LAC and its baselines.

Each algorithm's config module exposes the same names, so the CLI, the sweep, evaluation and the
docs treat every algorithm alike:

- ``CONFIG_CLASS``: its AlgorithmConfig (with :class:`~lac_rllib.constrained.task_config.SafeTaskConfig`
  mixed in), ``PARAMS`` its fields' dataclass and ``FIELDS`` their
  :class:`~lac_rllib.constrained.fields.FieldSet` (check, ``--set`` parser, docstrings);
- ``PRESETS``: per task family (``mujoco``, ``safety_gym``, ``tiny``: ``TaskSpec.preset``);
- ``SPEED_FIELDS``: fields that change how fast a run goes, not what it learns;
- ``ACTIONS``: what ``lac-eval --actions`` accepts for its policies;
- ``build_config(task, seed, sets, num_env_runners=0, timesteps=None, cpus=1)``: the validated config;
- optional, read through the functions below (an algorithm without them gets their defaults):
  ``BUDGET_FIELDS`` (a sweep's named budget → task preset or ``"*"`` → the fields it sets: the
  smoke and quick sizes), ``plan_update_s(params, preset)`` (the plan's estimate of its update
  seconds per env step on one CPU), and on ``CONFIG_CLASS`` ``REPORTED_KEYS`` (the learner's values
  an iteration's row carries) and ``TASK_FAMILY_OVERRIDES`` (fields per task family).

Imports are lazy: naming an algorithm costs nothing until it is built.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: algo → its config module. The order is the report's (LAC first).
ALGOS: dict[str, str] = {
    "lac": "lac_rllib.algorithms.lac.config",
    "ppo_lag": "lac_rllib.algorithms.ppo_lag.config",
    "sac_lag": "lac_rllib.algorithms.sac_lag.config",
}
DEFAULT_ALGO = "lac"
#: The name of the trial field that picks the algorithm (``--set algo=ppo_lag``, a grid over it).
ALGO_FIELD = "algo"


def check_algo(algo) -> str:
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; accepted: {' | '.join(ALGOS)}")
    return algo


def algo_config(algo: str) -> ModuleType:
    """The config module of ``algo`` (an unknown name raises a ValueError listing the accepted ones)."""
    return importlib.import_module(ALGOS[check_algo(algo)])


def algos_text(sep: str = " | ") -> str:
    """The algorithms' names as help texts and errors list them."""
    return sep.join(ALGOS)


def budget_fields(algo: str, budget: str, preset: str) -> dict:
    """The fields ``algo`` sets at the named ``budget`` on a task of ``preset`` (its
    ``BUDGET_FIELDS``; none declared: its preset's values)."""
    by_preset = getattr(algo_config(algo), "BUDGET_FIELDS", {}).get(budget, {})
    return dict(by_preset.get(preset, by_preset.get("*", {})))


def plan_update_s(algo: str, params: dict, preset: str) -> float:
    """The plan's estimate of ``algo``'s update seconds per env step on one CPU, beyond sampling
    (its ``plan_update_s``; none declared: 0, the estimate is the sampling alone)."""
    estimate = getattr(algo_config(algo), "plan_update_s", None)
    return float(estimate(params, preset)) if estimate else 0.0


def reported_keys(algo: str) -> tuple[str, ...]:
    """The learner's values an iteration's row of ``algo`` reports (``CONFIG_CLASS.REPORTED_KEYS``)."""
    return tuple(algo_config(algo).CONFIG_CLASS.REPORTED_KEYS)


def split_algo(sets: dict) -> tuple[str, dict]:
    """``{"algo": "sac_lag", "alpha": 0.1}`` → ("sac_lag", {"alpha": 0.1}); no ``algo``: LAC."""
    sets = dict(sets)
    return check_algo(sets.pop(ALGO_FIELD, DEFAULT_ALGO)), sets


def build_config(algo: str, task: str, seed: int, sets: dict, num_env_runners: int = 0,
                 timesteps: int | None = None, cpus: int = 1):
    """``algo``'s validated config for a run of ``timesteps`` env steps on ``task`` (no Ray needed)."""
    return algo_config(algo).build_config(task, seed, sets, num_env_runners=num_env_runners,
                                          timesteps=timesteps, cpus=cpus)


def parse_sets(algo: str, pairs: list[str]) -> dict:
    """``--set FIELD=VALUE`` pairs as ``algo``'s fields; a field of another algorithm is named as such."""
    fields = algo_config(algo).FIELDS
    try:
        return fields.parse_sets(pairs)
    except ValueError:
        for pair in pairs:
            name = pair.partition("=")[0].strip()
            if name not in fields.names:
                owners = [a for a in ALGOS if a != algo and name in algo_config(a).FIELDS.names]
                if owners:
                    raise ValueError(f"--set {name}: a field of {' and '.join(owners)}, not of {algo}; "
                                     f"accepted for {algo}: {', '.join(sorted(fields.names))}") from None
        raise
