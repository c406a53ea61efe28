"""The algorithms a run or a trial can name (``algo``), declared once: LAC and its baselines.

Each algorithm's config module exposes the same names, so the CLI, the sweep, evaluation and the
docs treat every algorithm alike:

- ``CONFIG_CLASS``: its AlgorithmConfig (with :class:`~lac_rllib.constrained.task_config.SafeTaskConfig`
  mixed in), ``PARAMS`` its fields' dataclass and ``FIELDS`` their
  :class:`~lac_rllib.constrained.fields.FieldSet` (check, ``--set`` parser, docstrings);
- ``PRESETS``: per task family (``mujoco``, ``safety_gym``, ``tiny``: ``TaskSpec.preset``);
- ``SPEED_FIELDS``: fields that change how fast a run goes, not what it learns, and ``ACTIONS``:
  what ``lac-eval --actions`` accepts for its policies; an algorithm that extends another (its
  *house*: :func:`house`, e.g. FOCOPS on PPO-Lag) may leave these, and every optional name below,
  to its house (:func:`declared` reads the algorithm's own, else its house's, and so on up);
- optional, read through the functions below (an algorithm without them, nor a house with them,
  gets their defaults): ``build_config(task, seed, sets, num_env_runners=0, timesteps=None,
  cpus=1)`` (the validated config; default ``CONFIG_CLASS.build``), ``BUDGET_FIELDS`` (a sweep's
  named budget → task preset or ``"*"`` → the fields it sets: the smoke and quick sizes),
  ``benchmark_fields(benchmark, steps)`` (what benchmarks/update_step.py and iteration.py build it
  with), ``plan_update_s(params, preset)`` (the plan's estimate of its update seconds per env step
  on one CPU), ``warmup_env_steps(params)`` (the env steps before its multiplier can act on the
  policy: early stopping waits for them, sweeps/scheduler.py), and on ``CONFIG_CLASS``
  ``REPORTED_KEYS`` (the learner's values an iteration's row carries) and ``TASK_FAMILY_OVERRIDES``
  (fields per task family).

A user's own algorithm is named by the import path of such a module (``mypkg.safe_algo``: a sweep
file's ``algo: {module: mypkg.safe_algo}``, ``--algo`` of lac-train, ``--set algo=``): that path
is its name everywhere (trial params, MLflow, ``config.json``, the checkpoint's ``algo``), so every
process imports it again by it. It is checked when first named (:func:`check_algo`: it imports,
exposes :data:`REQUIRED`, and its algorithm class names itself by the path in ``ALGO``), before Ray
starts; docs/baselines.md, "Your own algorithm", says how to write one.

Imports are lazy: naming an algorithm costs nothing until it is built.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
from types import ModuleType

from lac_rllib.errors import cut, excerpt

#: algo → its config module. The order is the report's (LAC first).
ALGOS: dict[str, str] = {
    "lac": "lac_rllib.algorithms.lac.config",
    "ppo_lag": "lac_rllib.algorithms.ppo_lag.config",
    "sac_lag": "lac_rllib.algorithms.sac_lag.config",
    "focops": "lac_rllib.algorithms.focops.config",
    "cup": "lac_rllib.algorithms.cup.config",
    "p3o": "lac_rllib.algorithms.p3o.config",
    "respo": "lac_rllib.algorithms.respo.config",
    "trpo_lag": "lac_rllib.algorithms.trpo_lag.config",
    "cpo": "lac_rllib.algorithms.cpo.config",
    "pcpo": "lac_rllib.algorithms.pcpo.config",
}
DEFAULT_ALGO = "lac"
#: The name of the trial field that picks the algorithm (``--set algo=ppo_lag``, a grid over it).
ALGO_FIELD = "algo"


#: The names every algorithm's config module exposes (the optional ones: the module docstring).
REQUIRED = ("CONFIG_CLASS", "PARAMS", "FIELDS", "PRESETS")
#: Names an algorithm declares or takes from its house (the algorithm it extends: :func:`declared`).
INHERITED = ("SPEED_FIELDS", "ACTIONS")
#: An import path: identifiers joined by dots (what a user's algorithm is named by).
MODULE_PATH = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
#: Users' modules checked in this process (import path → module): each is checked once.
_USER: dict[str, ModuleType] = {}


def check_algo(algo, search_dirs: tuple[str, ...] = ()) -> str:
    """``algo`` if it names an algorithm: a name of :data:`ALGOS`, or the import path of a user's
    module (imported from the Python path, else from the first of ``search_dirs`` holding it, and
    checked: :func:`user_module`). Else a one-line ValueError naming it and what is accepted."""
    if is_builtin(algo):
        return algo
    user_module(algo, search_dirs)
    return algo


def is_builtin(algo: str) -> bool:
    """Whether ``algo`` is one of the package's algorithms (else the import path of a user's)."""
    return isinstance(algo, str) and algo in ALGOS


def user_module(path, search_dirs: tuple[str, ...] = ()) -> ModuleType:
    """The config module of a user's algorithm, checked: it imports, it exposes :data:`REQUIRED`,
    and its algorithm class names itself ``path`` (``ALGO``), the name checkpoints restore it by."""
    if isinstance(path, str) and path in _USER:
        return _USER[path]
    accepted = f"accepted: {algos_text()}, or the import path of your own algorithm's module"
    if not (isinstance(path, str) and MODULE_PATH.fullmatch(path)):
        raise ValueError(f"unknown algo {excerpt(path)}; {accepted} (docs/baselines.md)")
    _find(path, search_dirs)
    try:
        module = importlib.import_module(path)
    except ModuleNotFoundError as e:
        if e.name and (path == e.name or path.startswith(e.name + ".")):  # the path itself, not what it imports
            where = "the Python path" + (f" nor {', '.join(search_dirs)}" if search_dirs else "")
            raise ValueError(f"unknown algo {path!r}; {accepted} (no module {e.name!r} on {where}; "
                             "docs/baselines.md)") from None
        raise ValueError(f"algo {path}: cannot be imported ({type(e).__name__}: {cut(str(e))})") from None
    except Exception as e:  # the user's own code: any exception, said in one line
        raise ValueError(f"algo {path}: cannot be imported ({type(e).__name__}: {cut(str(e))})") from None
    missing = [n for n in REQUIRED if not hasattr(module, n)]
    if missing:
        raise ValueError(f"algo {path}: its module lacks {', '.join(missing)}; accepted: a module exposing "
                         f"{', '.join(REQUIRED)} (docs/baselines.md, \"Your own algorithm\")")
    try:
        algo_class = module.CONFIG_CLASS().algo_class
    except Exception as e:  # the user's own code
        raise ValueError(f"algo {path}: CONFIG_CLASS() raised {type(e).__name__}: {cut(str(e))}") from None
    name = getattr(algo_class, "ALGO", None)
    if name != path:
        own = f" (or name the package's own as {name})" if is_builtin(name) else ""
        raise ValueError(f"algo {path}: its algorithm {getattr(algo_class, '__name__', algo_class)} names itself "
                         f"{name!r} (ALGO); accepted: ALGO = {path!r}, the path its runs and checkpoints name it "
                         f"by{own}")
    _USER[path] = module
    lacking = [n for n in INHERITED if declared(path, n) is None]
    if lacking:
        del _USER[path]
        raise ValueError(f"algo {path}: neither its module nor the algorithm it extends declares "
                         f"{', '.join(lacking)}; accepted: a module exposing {', '.join(REQUIRED + INHERITED)} "
                         "(docs/baselines.md, \"Your own algorithm\")")
    return module


def _find(path: str, search_dirs: tuple[str, ...]) -> None:
    """Put the first of ``search_dirs`` holding ``path``'s top-level module on ``sys.path``, unless
    the Python path has it already (a user's module beside the sweep file, as a user env's)."""
    top = path.split(".")[0]
    if importlib.util.find_spec(top) is not None:
        return
    for folder in search_dirs:
        if os.path.exists(os.path.join(folder, top + ".py")) or os.path.isdir(os.path.join(folder, top)):
            sys.path.append(folder)
            return


def module_dir(algo: str) -> str | None:
    """The folder a process puts on its path to import a user's ``algo`` (its top-level package's
    parent): Ray's workers do not share the driver's path. None: one of the package's algorithms."""
    if is_builtin(algo):
        return None
    check_algo(algo)
    top = sys.modules[algo.split(".")[0]]
    locations = list(getattr(top, "__path__", None) or [])  # a package (a namespace one has no __file__)
    return os.path.dirname(locations[0]) if locations else os.path.dirname(top.__file__)


def add_module_dir(folder: str | None) -> None:
    """Make a user's algorithm importable in this process (a trial's: :func:`module_dir`)."""
    if folder and folder not in sys.path:
        sys.path.append(folder)


def algo_config(algo: str) -> ModuleType:
    """The config module of ``algo`` (an unknown name raises a ValueError listing the accepted ones)."""
    if is_builtin(algo):
        return importlib.import_module(ALGOS[algo])
    return user_module(algo)


def algos_text(sep: str = " | ") -> str:
    """The algorithms' names as help texts and errors list them."""
    return sep.join(ALGOS)


def algorithm_class(algo: str) -> type:
    """``algo``'s RLlib Algorithm class (imports it: RLlib's modules load)."""
    from ray.rllib.utils.serialization import deserialize_type

    return deserialize_type(algo_config(algo).CONFIG_CLASS.ALGORITHM_CLASS, error=True)


def house(algo: str) -> str | None:
    """The package's algorithm that ``algo`` is built on: the nearest one whose algorithm class
    ``algo``'s extends (the first-order baselines: ``ppo_lag``, whose folder they import); None if
    it extends none (or names no class). Benchmarks time an algorithm against its house's step."""
    def resolved(a):
        try:
            return algorithm_class(a)
        except ValueError:  # a config without an algorithm class path: nothing to extend or be extended
            return None

    own = resolved(algo)
    classes = {c: a for a in ALGOS if a != algo and (c := resolved(a)) is not None}
    return next((classes[c] for c in own.__mro__[1:] if c in classes), None) if own is not None else None


def budget_fields(algo: str, budget: str, preset: str) -> dict:
    """The fields ``algo`` sets at the named ``budget`` on a task of ``preset`` (its
    ``BUDGET_FIELDS``; none declared: its preset's values)."""
    by_preset = declared(algo, "BUDGET_FIELDS", {}).get(budget, {})
    return dict(by_preset.get(preset, by_preset.get("*", {})))


def benchmark_fields(algo: str, benchmark: str, steps: int) -> dict:
    """The fields ``algo`` is built with to be timed by ``benchmark`` (``"update_step"``,
    ``"iteration"``) over ``steps`` (its ``benchmark_fields``; none declared: none)."""
    fields = declared(algo, "benchmark_fields")
    return dict(fields(benchmark, steps)) if fields else {}


def plan_update_s(algo: str, params: dict, preset: str) -> float:
    """The plan's estimate of ``algo``'s update seconds per env step on one CPU, beyond sampling
    (its ``plan_update_s``; none declared: 0, the estimate is the sampling alone)."""
    estimate = declared(algo, "plan_update_s")
    return float(estimate(params, preset)) if estimate else 0.0


def declared(algo: str, name: str, default=None):
    """What ``algo``'s module declares as ``name``, else what its house declares (the algorithm it
    extends: :func:`house`, and so on up), else ``default``."""
    while algo is not None:
        value = getattr(algo_config(algo), name, None)
        if value is not None:
            return value
        algo = house(algo)
    return default


def warmup_env_steps(algo: str, params: dict) -> int:
    """The env steps before ``algo``'s multiplier can act on its policy, for a trial's ``params``
    (its own or its house's ``warmup_env_steps``; none declared: 0). Early stopping waits for it
    (sweeps/scheduler.py)."""
    warmup = declared(algo, "warmup_env_steps")
    return int(warmup(params)) if warmup and params else 0


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
    build = getattr(algo_config(algo), "build_config", None) or algo_config(algo).CONFIG_CLASS.build
    return build(task, seed, sets, num_env_runners=num_env_runners, timesteps=timesteps, cpus=cpus)


def actions(algo: str) -> tuple[str, ...]:
    """What ``lac-eval --actions`` accepts for ``algo``'s policies (its or its house's ``ACTIONS``)."""
    return tuple(declared(algo, "ACTIONS"))


def speed_fields(algo: str) -> frozenset:
    """``algo``'s fields that change how fast a run goes, not what it learns (its or its house's)."""
    return frozenset(declared(algo, "SPEED_FIELDS"))


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
