"""The algorithms a run or a trial can name (``algo``): LAC and its baselines, each a config class.

Everything an algorithm declares is an attribute of its config class (a
:class:`~lac_rllib.constrained.task_config.SafeTaskConfig`), inherited as Python inherits: ``ALGO``
(its name), ``PARAMS`` and ``FIELDS`` (its fields, their checks and docstrings), ``PRESETS`` (per
task family: ``mujoco``, ``safety_gym``, ``tiny``: ``TaskSpec.preset``), its three RLlib classes,
``REPORTED_KEYS``, ``TASK_FAMILY_OVERRIDES``, ``ACTIONS`` (what ``lac-eval --actions`` accepts),
``SPEED_FIELDS``, ``BUDGET_FIELDS`` (a sweep's named budgets), ``build`` (the validated config of
a run), ``benchmark_fields``, ``plan_update_s`` (the plan's estimate of its update seconds per env
step) and ``warmup_env_steps`` (early stopping waits for them). An algorithm that extends another
(its *house*: FOCOPS on PPO-Lag) extends its config class and declares only what differs.

This module maps names to those classes (:data:`ALGOS`), reads them for the CLI, the sweep, lac-eval
and the benchmarks, and checks a user's algorithm: one named by the import path of its module
(``mypkg.safe_algo``: a sweep file's ``algo: {module: mypkg.safe_algo}``, ``--algo`` of lac-train,
``--set algo=``), which defines one config class (the one whose ``ALGO`` is that path, as a
config class names itself by its module unless it says otherwise) and its learner. That path is
its name everywhere (trial params, MLflow, ``config.json``, the checkpoint's ``algo``), so every
process imports it again by it. It is checked when first named (:func:`check_algo`), before Ray
starts; docs/baselines.md, "Your own algorithm", says how to write one.

Imports are lazy: naming an algorithm costs nothing until it is built.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import os
import re
import sys

from lac_rllib.errors import announce, cut, excerpt

#: algo → its config class, as an import path. The order is the report's (LAC first).
ALGOS: dict[str, str] = {
    "lac": "lac_rllib.algorithms.lac.config.LACConfig",
    "ppo_lag": "lac_rllib.algorithms.ppo_lag.config.PPOLagConfig",
    "sac_lag": "lac_rllib.algorithms.sac_lag.config.SACLagConfig",
    "focops": "lac_rllib.algorithms.focops.config.FOCOPSConfig",
    "cup": "lac_rllib.algorithms.cup.config.CUPConfig",
    "p3o": "lac_rllib.algorithms.p3o.config.P3OConfig",
    "respo": "lac_rllib.algorithms.respo.config.RESPOConfig",
    "trpo_lag": "lac_rllib.algorithms.trpo_lag.config.TRPOLagConfig",
    "cpo": "lac_rllib.algorithms.cpo.config.CPOConfig",
    "pcpo": "lac_rllib.algorithms.pcpo.config.PCPOConfig",
}
DEFAULT_ALGO = "lac"
#: The name of the trial field that picks the algorithm (``--set algo=ppo_lag``, a grid over it).
ALGO_FIELD = "algo"

#: An import path: identifiers joined by dots (what a user's algorithm is named by).
MODULE_PATH = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
#: Users' algorithms checked in this process (import path → config class): each is checked once.
_USER: dict[str, type] = {}
#: Users' modules announced in this process (errors.announce: once each, before their import).
_ANNOUNCED: set[str] = set()


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


def user_module(path, search_dirs: tuple[str, ...] = ()) -> type:
    """The config class of a user's algorithm, checked: its module imports (said on stderr first:
    a slow or hanging import is the user's code, never a silent CLI) and defines exactly one
    config class (a SafeTaskConfig) named by ``path`` (``ALGO``), the name checkpoints restore it by."""
    if isinstance(path, str) and path in _USER:
        return _USER[path]
    accepted = f"accepted: {algos_text()}, or the import path of your own algorithm's module"
    if not (isinstance(path, str) and MODULE_PATH.fullmatch(path)):
        raise ValueError(f"unknown algo {excerpt(path)}; {accepted} (docs/baselines.md)")
    _find(path, search_dirs)
    top = path.split(".")[0]
    if path not in sys.modules and path not in _ANNOUNCED and importlib.util.find_spec(top) is not None:
        _ANNOUNCED.add(path)  # said once: a slow or hanging import is the user's code, never silence
        announce(f"importing your algorithm's module {path}")
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
    from lac_rllib.constrained.task_config import SafeTaskConfig

    own = [c for c in vars(module).values()
           if isinstance(c, type) and issubclass(c, SafeTaskConfig) and c.__module__ == module.__name__]
    named = [c for c in own if c.ALGO == path]
    if len(named) != 1:
        found = ", ".join(f"{c.__name__} (ALGO {c.ALGO!r})" for c in own) or "none"
        raise ValueError(f"algo {path}: its module must define one config class named {path!r} (ALGO); found "
                         f"{found}; accepted: a subclass of a package algorithm's config (e.g. PPOLagConfig) "
                         "defined in the module, which names itself by it (docs/baselines.md, \"Your own algorithm\")")
    config_cls = named[0]
    missing = [n for n in ("FIELDS", "LEARNER_CLASS", "ALGORITHM_CLASS") if not getattr(config_cls, n, None)]
    if missing:
        raise ValueError(f"algo {path}: {config_cls.__name__} declares no {', '.join(missing)}; accepted: a config "
                         "class extending a package algorithm's (docs/baselines.md, \"Your own algorithm\")")
    try:
        config_cls()
    except Exception as e:  # the user's own code
        raise ValueError(f"algo {path}: {config_cls.__name__}() raised {type(e).__name__}: {cut(str(e))}") from None
    _USER[path] = config_cls
    return config_cls


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


def algo_config(algo: str) -> type:
    """``algo``'s config class (an unknown name raises a ValueError listing the accepted ones)."""
    if is_builtin(algo):
        return _import_class(ALGOS[algo])
    return user_module(algo)


@functools.cache
def _import_class(path: str) -> type:
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


def algos_text(sep: str = " | ") -> str:
    """The algorithms' names as help texts and errors list them."""
    return sep.join(ALGOS)


def algorithm_class(algo: str) -> type:
    """``algo``'s RLlib Algorithm class (imports it: RLlib's modules load)."""
    from ray.rllib.utils.serialization import deserialize_type

    return deserialize_type(algo_config(algo).ALGORITHM_CLASS, error=True)


def house(algo: str) -> str | None:
    """The package's algorithm that ``algo`` is built on: the nearest one whose config class
    ``algo``'s extends (FOCOPS, CUP, RESPO: ``ppo_lag``; PCPO: ``cpo``; a user's: the one it
    extends); None if it extends none (PPO-Lag, P3O, TRPO-Lag and CPO extend the family bases of
    lac_rllib/families/). An algorithm folder imports from no other but its house's, and
    benchmarks time an algorithm against its house's step."""
    builtin = {algo_config(a): a for a in ALGOS}
    return next((builtin[c] for c in algo_config(algo).__mro__[1:] if c in builtin), None)


def budget_fields(algo: str, budget: str, preset: str) -> dict:
    """The fields ``algo`` sets at the named ``budget`` on a task of ``preset`` (its
    ``BUDGET_FIELDS``; none declared: its preset's values)."""
    by_preset = algo_config(algo).BUDGET_FIELDS.get(budget, {})
    return dict(by_preset.get(preset, by_preset.get("*", {})))


def benchmark_fields(algo: str, benchmark: str, steps: int) -> dict:
    """The fields ``algo`` is built with to be timed by ``benchmark`` (``"update_step"``,
    ``"iteration"``) over ``steps``."""
    return dict(algo_config(algo).benchmark_fields(benchmark, steps))


def plan_update_s(algo: str, params: dict, preset: str) -> float:
    """The plan's estimate of ``algo``'s update seconds per env step on one CPU, beyond sampling."""
    return float(algo_config(algo).plan_update_s(params, preset))


def warmup_env_steps(algo: str, params: dict) -> int:
    """The env steps before ``algo``'s multiplier can act on its policy, for a trial's ``params``
    (0 without params). Early stopping waits for it (sweeps/scheduler.py)."""
    return int(algo_config(algo).multiplier_warmup(params)) if params else 0


def split_algo(sets: dict) -> tuple[str, dict]:
    """``{"algo": "sac_lag", "alpha": 0.1}`` → ("sac_lag", {"alpha": 0.1}); no ``algo``: LAC."""
    sets = dict(sets)
    return check_algo(sets.pop(ALGO_FIELD, DEFAULT_ALGO)), sets


def build_config(algo: str, task: str, seed: int, sets: dict, num_env_runners: int = 0,
                 timesteps: int | None = None, cpus: int = 1):
    """``algo``'s validated config for a run of ``timesteps`` env steps on ``task`` (no Ray needed)."""
    return algo_config(algo).build(task, seed, sets, num_env_runners=num_env_runners, timesteps=timesteps,
                                   cpus=cpus)


def has_multiplier(algo: str) -> bool:
    """Whether ``algo`` has a Lagrange multiplier one can hold fixed (its field ``nu_fixed``):
    what the fixed-multiplier frontier and ``lac-sweep calibrate`` need."""
    return "nu_fixed" in algo_config(algo).FIELDS.names


def with_multiplier_text() -> str:
    """The package's algorithms that have one, as refusals list them."""
    return " | ".join(a for a in ALGOS if has_multiplier(a))


def actions(algo: str) -> tuple[str, ...]:
    """What ``lac-eval --actions`` accepts for ``algo``'s policies."""
    return tuple(algo_config(algo).ACTIONS)


def search_space(algo: str) -> dict:
    """``algo``'s declared search space: field → :class:`~lac_rllib.constrained.search_space.Searched`."""
    return dict(algo_config(algo).SEARCH_SPACE)


def changeable_space(algo: str) -> dict:
    """The fields PBT may change mid-run in ``algo``, with their ranges (``CHANGEABLE``)."""
    return algo_config(algo).changeable_space()


def speed_fields(algo: str) -> frozenset:
    """``algo``'s fields that change how fast a run goes, not what it learns."""
    return frozenset(algo_config(algo).SPEED_FIELDS)


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
