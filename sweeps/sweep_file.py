"""Sweep files: what a sweep runs, declared in YAML (``sweeps/run.py --config FILE.yaml``).

The schema is a pydantic model (:class:`SweepFile`), each key declared once with a docstring
below it: docs/sweeps.md's reference is generated from it (``python -m sweeps.sweep_file``). A
file is checked in two passes before Ray starts, and every error is one line naming the file,
the line, the key path and what is accepted:

0. the text (sweeps/bounded_yaml.py): size, encoding, nesting depth, aliases and what they expand
   to, duplicate keys, all bounded before anything is built;
1. the structure (:meth:`SweepFile.model_validate`): unknown keys (with the closest name), types
   (strict: a boolean is never taken for a number), ranges and counts, names that become paths,
   one distribution per searched field, an empty grid, an algorithm that is neither a name of the
   registry nor a user's module (``{module: mypkg.safe_algo}``) that imports and exposes its names;
2. the fields (:func:`check_fields`): every field in ``set``, ``grid``, ``groups`` and ``search``
   against the declaration of each algorithm the trial runs (lac_rllib/algorithms/registry.py):
   an unknown field (with the closest name), a value or distribution outside what the field
   accepts, a field that belongs to another algorithm.

The built-in spaces are files in ``sweeps/builtin/`` (``--space NAME`` reads ``NAME.yaml``).
A resolved sweep (defaults and flags applied) is again a :class:`SweepFile`: ``sweep.yaml`` in the
parent run and beside Tune's state is a file that reruns the same sweep.
"""

from __future__ import annotations

import builtins
import difflib
import os
import re
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    StringConstraints,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from lac_rllib.algorithms.registry import DEFAULT_ALGO
from lac_rllib.errors import excerpt
from sweeps.bounded_yaml import YamlRefused
from sweeps.bounded_yaml import read as read_yaml
from sweeps.bounded_yaml import read_text as read_yaml_text
from sweeps.search import TPE_STARTUP, random_start, steered

BUILTIN_DIR = Path(__file__).with_name("builtin")
BUDGET_NAMES = ("smoke", "quick", "paper")
SEARCHERS = ("grid", "random", "tpe", "motpe", "nsga2")
#: Searchers over two objectives (return up, cost down; the limit as a constraint): the Pareto set.
MULTI_OBJECTIVE = ("motpe", "nsga2")
Scalar = bool | int | float | str | None

# Bounds on what one file may ask for: far above any sweep one machine or a modest cluster runs,
# far below what would exhaust the driver's memory while the plan is made (the trial count itself
# is bounded at plan time: sweeps/run.py --max-trials).
MAX_SEEDS = 1_000  #: seeds per configuration
MAX_SEED = 2**31 - 1  #: numpy's and gymnasium's seeds are 32-bit
MAX_VALUES = 1_000  #: values of one grid field or one choice
MAX_SAMPLES = 100_000  #: configurations a search samples
MAX_BUDGET = 10**10  #: env steps per trial (the paper's is 2.5M)
MAX_CPUS = 4_096  #: CPUs per trial, trials at once
MAX_TEXT = 2_000  #: a description's characters


class SweepFileError(ValueError):
    """A bad sweep file: ``FILE:LINE: key.path: what is wrong; accepted: ...`` (one line)."""


class KeyedError(ValueError):
    """A model validator's error that belongs to one key (``loc``), so the line can name it."""

    def __init__(self, loc: tuple, message: str):
        super().__init__(message)
        self.loc = loc


def Int(low: int, high: int):  # noqa: N802 (a type)
    """An integer in [low, high]; strict: ``true`` is not 1 and ``2.0`` is not 2."""
    return Annotated[int, Field(strict=True, ge=low, le=high)]


#: A finite number; strict: ``true`` is not 1.0, ``"1"`` is not 1.0 (an integer is a number).
Real = Annotated[float, Field(strict=True, allow_inf_nan=False)]

#: A name that becomes a path or part of one (a sweep's directory under --storage, a group's
#: trial names): ASCII letters, digits, ``_ . -``, not starting with ``.`` or ``-``, no ``..``.
SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,99}")
SAFE_NAME_TEXT = ("letters, digits, _ . - (ASCII; not starting with . or -, no '..', "
                  "at most 100 characters)")


def check_name(v: str, what: str = "name") -> str:
    """``v`` if it is a safe name (:data:`SAFE_NAME`), else a ValueError naming it and the rule."""
    if not isinstance(v, str) or not SAFE_NAME.fullmatch(v) or ".." in v:
        raise ValueError(f"{what} {excerpt(v)} is refused (it becomes a path); accepted: {SAFE_NAME_TEXT}")
    return v


def _task_name(v: str) -> str:
    """A user task's name: safe names joined by ``/`` (``user/my-env``), none empty or ``..``."""
    parts = v.split("/") if isinstance(v, str) else [v]
    if len(parts) > 4 or any(not SAFE_NAME.fullmatch(p) or ".." in p for p in parts):
        raise ValueError(f"name {excerpt(v)} is refused; accepted: up to 4 parts joined by /, each of "
                         f"{SAFE_NAME_TEXT}")
    return v


def _display_name(v: str) -> str:
    """An MLflow experiment's name: printable text, no surrounding blanks, 1..200 characters."""
    if not (0 < len(v) <= 200 and v.isprintable() and v == v.strip()):
        raise ValueError(f"experiment {excerpt(v)} is refused; accepted: 1..200 printable characters, "
                         "no leading or trailing blanks")
    return v


def safe_name(text: str) -> str:
    """A name derived from something else (a file's stem, a task id) made safe rather than refused:
    every character outside the safe set becomes ``_``."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", text).replace("..", "_").lstrip(".-")[:100]
    return name or "sweep"


SafeName = Annotated[str, AfterValidator(check_name)]


def _budget_value(v: Any) -> Any:
    if v is None or (isinstance(v, str) and v in BUDGET_NAMES):
        return v
    if isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= MAX_BUDGET:
        return v
    what = "unknown budget" if isinstance(v, str) else "budget"
    raise ValueError(f"{what} {excerpt(v)} is invalid; accepted: {' | '.join(BUDGET_NAMES)} or env steps "
                     f"(an integer 1..{MAX_BUDGET:,})")


def _schema_config(**extra) -> ConfigDict:
    return ConfigDict(extra="forbid", use_attribute_docstrings=True, frozen=True, **extra)


class Seeds(BaseModel):
    """``count`` seeds from ``start``: start, start + 1, ...; or an explicit ``list``."""

    model_config = _schema_config()
    count: Int(1, MAX_SEEDS) | None = None
    """How many seeds per configuration (a search: per sampled configuration)."""
    start: Int(0, MAX_SEED) = 0
    """The first seed: confirmation runs start past the seeds a search saw (e.g. 100)."""
    list: Annotated[tuple[Int(0, MAX_SEED), ...], Field(max_length=MAX_SEEDS)] | None = None
    """The seeds themselves (instead of count and start); distinct."""

    @model_validator(mode="after")
    def _one_form(self):
        if (self.count is None) == (self.list is None):
            raise ValueError("give count (and start) or list")
        if self.list is not None and (not self.list or len(set(self.list)) != len(self.list)):
            raise KeyedError(("list",), f"{excerpt(builtins.list(self.list))} must hold distinct seeds, at least one")
        if self.count is not None and self.start + self.count - 1 > MAX_SEED:
            raise KeyedError(("start",), f"seeds {self.start}..{self.start + self.count - 1} pass {MAX_SEED}; "
                                         f"accepted: seeds up to {MAX_SEED}")
        return self

    def values(self) -> tuple[int, ...]:
        return tuple(self.list) if self.list is not None else tuple(range(self.start, self.start + self.count))


def _seeds_form(v: Any) -> Any:
    """``3`` → {count: 3}; ``[100, 101]`` → {list: [...]}: the short forms a file may use."""
    if isinstance(v, bool):
        return v
    if isinstance(v, int):
        return {"count": v}
    if isinstance(v, (list, tuple)):
        return {"list": v}
    return v


def _algo_name(v: Any) -> Any:
    """``{module: "mypkg.safe_algo"}`` → ``"mypkg.safe_algo"``: a user's algorithm is named by its
    import path everywhere after the file (trial params, MLflow, checkpoints)."""
    if not isinstance(v, dict):
        return v
    if set(v) != {"module"} or not isinstance(v["module"], str):
        raise ValueError(f"{excerpt(v)}: accepted: an algorithm's name, or your own algorithm's module as "
                         "{module: IMPORT.PATH} (docs/baselines.md)")
    return v["module"]


def _search_dirs(info: ValidationInfo | None) -> tuple[str, ...]:
    """Where a user's module is looked for beyond the Python path (the file's folder, the working
    directory): handed to validation as its context by :func:`load_with_origin`."""
    return tuple(((info.context if info else None) or {}).get("search_dirs", ()))


class UserEnv(BaseModel):
    """An env lac-rllib does not ship: built by ``factory`` (``"module:function"``, called with the
    env config dict) or made from a registered gymnasium ``id`` (``"module:Env-v0"`` imports the
    module first), whose per-step cost is ``info[cost_key]``. Before Ray starts the service builds
    it once and steps it, and refuses one whose spaces are not flat Boxes or whose info has no cost."""

    model_config = _schema_config()
    factory: str | None = Field(None, pattern=r"^[\w.]+:\w+$")
    """``"package.module:function"``: called as ``function(env_config)``, returns a gymnasium env."""
    id: str | None = Field(None, min_length=1, max_length=200)
    """A registered gymnasium id (``gym.make(id)``), instead of ``factory``."""
    cost_limit: Real = Field(ge=0)
    """b, the limit on the episode cost (required: there is no sensible default)."""
    episode_cost_discount: Real = Field(1.0, gt=0, le=1)
    """γ_C of the episode cost the multiplier reads: 1 sums the per-step costs (Safety-Gym's convention)."""
    cost_key: str = Field("cost", min_length=1, max_length=100)
    """The key of ``info`` that holds the step's cost."""
    preset: Literal["mujoco", "safety_gym", "tiny"] = "mujoco"
    """Which family's preset the algorithms start from (docs/config.md): ``mujoco`` is the paper's
    Table 4 for continuous control, the general case."""
    kwargs: dict[str, Any] = {}
    """Passed to the factory (merged into its env config) or to ``gym.make``."""
    constraints: dict[Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]{1,60}$")],
                      Annotated[str, StringConstraints(min_length=1, max_length=100)]] | None = None
    """Its constraints, each a name and the ``info`` key of its step cost (``{speed: speed_cost}``), that a
    sweep's ``constraints`` may give limits (docs/constraints.md); checked on its first steps."""
    name: Annotated[str, AfterValidator(_task_name)] | None = None
    """The task's name in the sweep, its runs and labels (default: ``user/<function or id>``)."""

    @model_validator(mode="after")
    def _one_source(self):
        if (self.factory is None) == (self.id is None):
            raise ValueError("give factory or id (one of them)")
        return self

    def task_id(self) -> str:
        return self.name or "user/" + (self.factory or self.id).replace(":", ".")


TaskRef = Annotated[
    Annotated[str, Tag("<task id>")] | Annotated[UserEnv, Tag("<user env>")],
    Discriminator(lambda v: "<user env>" if isinstance(v, (dict, UserEnv)) else "<task id>"),
]


class Distribution(BaseModel):
    """One searched field's distribution: exactly one key."""

    model_config = _schema_config()
    choice: tuple[Scalar, ...] | None = Field(None, min_length=1, max_length=MAX_VALUES)
    """One of these values (numbers, strings, booleans, null: Optuna's categorical)."""
    uniform: tuple[Real, Real] | None = None
    """[low, high]."""
    loguniform: tuple[Real, Real] | None = None
    """[low, high], low > 0: uniform in log space."""
    int: tuple[Annotated[builtins.int, Field(strict=True)], Annotated[builtins.int, Field(strict=True)]] | None = None
    """[low, high]: an integer, both ends included."""
    quniform: tuple[Real, Real, Real] | None = None
    """[low, high, q]: uniform, rounded to a multiple of q (quantised)."""

    @field_validator("choice", mode="before")
    @classmethod
    def _scalars(cls, v):
        if isinstance(v, (list, tuple)) and any(isinstance(c, (list, tuple, dict)) for c in v):
            raise ValueError(f"{excerpt(list(v))}: choice values are numbers, strings, booleans or null (Optuna's "
                             "categorical); accepted for lists such as layer sizes: a grid")
        return v

    @model_validator(mode="after")
    def _exactly_one(self):
        given = [k for k in type(self).model_fields if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of {', '.join(type(self).model_fields)} "
                             f"(got {', '.join(given) or 'none'})")
        kind, args = self.kind, self.args
        if kind != "choice" and not args[0] < args[1]:
            raise ValueError(f"{kind}: low {args[0]} must be below high {args[1]}")
        if kind == "loguniform" and args[0] <= 0:
            raise ValueError(f"loguniform: low {args[0]} must be > 0")
        if kind == "quniform" and args[2] <= 0:
            raise ValueError(f"quniform: q {args[2]} must be > 0")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in type(self).model_fields if getattr(self, k) is not None)

    @property
    def args(self) -> tuple:
        return getattr(self, self.kind)

    def values_to_check(self) -> list:
        """The values a field must accept for this distribution to be valid: its choices or its ends."""
        return list(self.args) if self.kind == "choice" else list(self.args[:2])


def _grid_lists(grid: dict) -> dict:
    for name, values in grid.items():
        if not values:
            raise KeyedError((name,), "an empty list of values; accepted: a non-empty list")
    return grid


#: A grid: field → its values (one configuration per combination; their count is bounded at plan time).
Grid = dict[str, Annotated[tuple[Any, ...], Field(max_length=MAX_VALUES)]]


#: A cost limit or a fixed multiplier: a finite number >= 0.
NonNegative = Annotated[Real, Field(ge=0)]


def _distinct(v: tuple | None) -> tuple | None:
    if v is not None and len(set(v)) != len(v):
        raise ValueError(f"{excerpt(list(v))} repeats a value; accepted: distinct numbers >= 0")
    return v


class Frontier(BaseModel):
    """The fixed-multiplier frontier: ``algo`` run with its Lagrange multiplier frozen at each of
    ``nu`` for the whole run (its field ``nu_fixed``), every seed, on every task; the trained
    policies' scores trace the task's empirical return-cost front, against which the report measures
    every configuration's regret at each cost limit (docs/sweeps.md, "Across a ladder of cost limits")."""

    model_config = _schema_config()

    algo: str
    """The algorithm, one with a Lagrange multiplier (its fields have ``nu_fixed``)."""
    nu: tuple[NonNegative, ...] = Field(min_length=1, max_length=MAX_VALUES)
    """The fixed values of ν, distinct, each >= 0 (0: the unconstrained algorithm)."""

    _nu = field_validator("nu")(classmethod(lambda cls, v: _distinct(v)))

    @field_validator("algo", mode="before")
    @classmethod
    def _algo_form(cls, v):
        return _algo_name(v)

    @field_validator("algo")
    @classmethod
    def _with_multiplier(cls, v, info: ValidationInfo):
        from lac_rllib.algorithms.registry import check_algo, has_multiplier, with_multiplier_text

        check_algo(v, _search_dirs(info))
        if not has_multiplier(v):
            raise ValueError(f"{v} has no Lagrange multiplier to fix; accepted: {with_multiplier_text()}")
        return v


class ScheduleStep(BaseModel):
    """One change of a schedule: from env step ``at`` on, the fields in ``set``."""

    model_config = _schema_config()
    at: Int(0, MAX_BUDGET)
    """Env steps from which it applies (the first iteration that starts at or after them)."""
    set: dict[str, Any] = Field(min_length=1)
    """The changeable fields it sets (each algorithm's: docs/config.md "Search spaces")."""


class Group(BaseModel):
    """Named configurations: every combination of ``grid``'s values, each with ``set`` on top."""

    model_config = _schema_config()
    grid: Grid = {}
    """field → values: one configuration per combination (none: one configuration, ``set`` alone)."""
    set: dict[str, Any] = {}
    """Fields this group's configurations set (the sweep's ``set`` below them, ``grid`` above)."""
    schedule: tuple[ScheduleStep, ...] | None = Field(None, min_length=1, max_length=MAX_VALUES)
    """A schedule its changeable fields follow during training, ascending in ``at`` (a PBT winner's,
    replayed: sweeps/pbt.py); each change rebuilds the run with the new fields and its own state."""

    _lists = field_validator("grid")(classmethod(lambda cls, v: _grid_lists(v)))

    @field_validator("schedule")
    @classmethod
    def _ascending(cls, v):
        if v is not None and any(b.at <= a.at for a, b in zip(v, v[1:])):
            raise ValueError(f"at {[e.at for e in v]}: accepted: strictly ascending env steps")
        return v


class PBTSpec(BaseModel):
    """Population-based training (``searcher: pbt``, sweeps/pbt.py): ``members`` runs of the
    algorithm, one seed each, exploiting within their sub-population at its ``interval``, ranked by
    the one feasibility rule on their last ``window`` iterations."""

    model_config = _schema_config()
    members: Int(2, 1_000) = 8
    """The population's size (each member its own seed, from the sweep's first seed on)."""
    interval: Int(1, MAX_BUDGET) | tuple[Int(1, MAX_BUDGET), ...] | None = None
    """Env steps between exploits: one number, or one per sub-population (MF-PBT: the members split
    round-robin, the best of a slower one migrating into the next faster one); default an eighth of
    the budget. Each shorter than the budget."""
    growth: Annotated[float, Field(strict=True, ge=1.0, le=10.0)] = 1.0
    """Each exploit multiplies its sub-population's interval by this (IPBT grows it); 1: fixed."""
    quantile: Annotated[float, Field(strict=True, gt=0.0, le=0.5)] = 0.25
    """The bottom fraction of a sub-population that copies a member of its top fraction (Tune's)."""
    window: Int(1, 1_000) = 5
    """Iterations whose means rank a member (its return and each constraint's cost)."""
    resample_probability: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.25
    """The chance an exploited field is drawn again from its range instead of scaled ×0.8 or ×1.2."""
    migrate: bool = True
    """With several intervals: the best of a slower sub-population migrates into the next faster."""

    def intervals(self, budget: int) -> tuple[int, ...]:
        """The sub-populations' intervals, fastest first (default: an eighth of ``budget``)."""
        if self.interval is None:
            return (max(1, budget // 8),)
        return tuple(sorted(self.interval)) if isinstance(self.interval, tuple) else (self.interval,)


class GroupsAt(BaseModel):
    """Groups that replace ``groups`` where a trial's budget and task preset match: the default
    ablation runs a reduced Table 3 at the quick budget on the tiny task."""

    model_config = _schema_config()
    budget: str | int | None = None
    """The budget this applies at (``smoke | quick | paper`` or env steps; none: any)."""
    preset: Literal["mujoco", "safety_gym", "tiny"] | None = None
    """The task preset this applies to (none: any)."""
    groups: dict[SafeName, Group] = Field(min_length=1)
    """The groups there."""

    _budget = field_validator("budget", mode="before")(classmethod(lambda cls, v: _budget_value(v)))


class TuneSpec(BaseModel):
    """The equal budget of a tuned comparison: each algorithm gets ``num_samples`` configurations of
    its search space, each trained with ``seeds`` seeds, at the sweep's budget, under ``searcher`` (the
    constrained TPE by default); then its ``top`` best are confirmed beside its default on
    ``confirm_seeds`` fresh seeds, every algorithm in the same confirmation."""

    model_config = _schema_config()
    searcher: Literal["random", "tpe", "pbt"] = "tpe"
    """How every algorithm is searched: Optuna's ``tpe`` (with the feasibility constraint; its first
    half of the samples, at most 10, are its random start) or ``random``, or population-based
    training, ``pbt`` (each algorithm's population of ``pbt.members`` over its changeable fields; its
    winner's schedule confirmed and registered)."""
    pbt: PBTSpec | None = None
    """With ``searcher: pbt``: every algorithm's population (:class:`PBTSpec`; default 8 members)."""
    num_samples: Int(1, MAX_SAMPLES) = 8
    """Configurations each algorithm's search samples (with ``tpe`` at least 2: one steered by TPE)."""
    seeds: Seeds = Seeds(count=3)
    """Seeds per sampled configuration (``3``, ``{count: 3, start: 0}`` or a list)."""
    confirm_seeds: Int(1, MAX_SEEDS) = 5
    """Fresh seeds of the confirmation (after the search's largest), for every winner and default."""
    top: Int(1, 10) = 1
    """Configurations per algorithm confirmed (the registry keeps the first)."""

    _seeds = field_validator("seeds", mode="before")(classmethod(lambda cls, v: _seeds_form(v)))

    @model_validator(mode="after")
    def _steered(self):
        if self.pbt is not None and self.searcher != "pbt":
            raise KeyedError(("pbt",), f"pbt with searcher {self.searcher}; accepted: with searcher: pbt")
        if self.searcher == "pbt":
            for key in ("num_samples", "seeds"):  # (a resolved file dumps the defaults: those pass)
                if getattr(self, key) != type(self).model_fields[key].default:
                    raise KeyedError((key,), f"{key} with searcher pbt: a population of pbt.members runs, one seed "
                                     "each; accepted: pbt: {members: N}")
            if self.pbt is None:
                object.__setattr__(self, "pbt", PBTSpec())
            return self
        # A "tuned" comparison whose every draw is TPE's random start is random search (sweeps/search.py).
        if self.searcher == "tpe" and steered(self.searcher, self.num_samples) == 0:
            start = random_start(self.searcher, self.num_samples)
            raise KeyedError(("num_samples",), f"num_samples {self.num_samples} with searcher tpe: all {start} "
                                               f"come from TPE's random start, none is steered by TPE; accepted: "
                                               f"num_samples >= 2 with tpe (half of them its random start, at "
                                               f"most {TPE_STARTUP}), or searcher random")
        return self


class SweepFile(BaseModel):
    """A sweep: task(s) × algorithm(s) × configurations × seeds at one budget, searched or gridded.

    Every key is optional; what a file leaves out comes from the command line's flags, then from
    the defaults shown here. Flags given on the command line win over the file."""

    model_config = _schema_config()
    description: str | None = Field(None, max_length=MAX_TEXT)
    """What the sweep is for (shown in the plan and the parent run's note)."""
    name: SafeName | None = None
    """The sweep's name: its Tune directory and MLflow parent run; ``--resume`` finds it by name
    (default: FILE-TASK-BUDGET)."""
    task: tuple[TaskRef, ...] | None = Field(None, min_length=1)
    """A task id (docs/tasks.md), a user env (``{factory: "pkg.mod:make", cost_limit: 10}``) or a
    list of them; default ``lac/PointHazard-v0``."""
    algo: tuple[str, ...] = (DEFAULT_ALGO,)
    """The algorithm (a name of the registry, lac_rllib/algorithms/registry.py: docs/config.md lists
    each with its fields; or your own algorithm's module, ``{module: "mypkg.safe_algo"}`` or its
    import path as a string: docs/baselines.md) or a list (every configuration runs with each)."""
    budget: str | int | None = None
    """Env steps per trial: a named budget (``smoke | quick | paper``, with the overrides that make
    it meaningful: docs/sweeps.md) or a number of env steps in [1, 10¹⁰] (the presets' fields);
    default quick."""
    seeds: Seeds | None = None
    """A count (``3``), ``{count: 3, start: 100}``, or a list (``[100, 101, 102]``); default 3 from 0."""
    set: dict[str, Any] = {}
    """Fields every trial sets (as ``--set``; docs/config.md lists each algorithm's)."""
    grid: Grid | None = None
    """field → values: one configuration per combination (the file's one group)."""
    groups: dict[SafeName, Group] | None = None
    """Named groups of configurations, the sweep runs all of them (e.g. Table 3's NI, VT, PR)."""
    groups_at: tuple[GroupsAt, ...] = ()
    """Groups used instead of ``groups`` at a budget and task preset (the first match wins)."""
    search: Literal["default", "pbt"] | dict[str, Distribution | Literal["default"]] | None = None
    """field → distribution, sampled ``num_samples`` times by ``searcher``; ``default``: the algorithm's
    declared search space (its important fields with ranges and sources, docs/config.md "Search
    spaces"), or, as one field's value, that field's declared range (a narrower search: name only
    some of its fields, or give some a range of your own); ``pbt``: ``default`` searched by
    population-based training (``searcher: pbt``)."""
    searcher: Literal["grid", "random", "tpe", "motpe", "nsga2", "pbt"] | None = None
    """``grid`` (``grid``/``groups``; the default without ``search``), ``random`` (Optuna's random
    sampler), ``tpe`` (Optuna's TPE on one objective with the feasibility constraint; the default with
    ``search``), or a multi-objective search on return and cost with the constraint, whose result is
    the Pareto set: ``motpe`` (Optuna's TPE on two objectives) or ``nsga2`` (NSGA-II). TPE's random
    start (NSGA-II's random first generation) is half the samples, at most Optuna's default (10; 50):
    the plan says how many draws each steers. ``pbt``: population-based training over the search's
    changeable fields (``pbt``)."""
    pbt: PBTSpec | None = None
    """With ``searcher: pbt``: the population, its exploit intervals and ranking window (:class:`PBTSpec`)."""
    num_samples: Int(1, MAX_SAMPLES) | None = None
    """Configurations a search samples (each trained with every seed); default 20."""
    env_steps_budget: Int(1, MAX_BUDGET * MAX_SAMPLES) | None = None
    """With a search: the env steps it may spend in all. A configuration is drawn only while what the
    finished ones spent, plus a full budget for each one running and for the new one, stays within
    it, so an early stop (``asha``) frees its rest for more draws; ``num_samples`` is then an upper
    bound. What compares a search with PBT (members × budget) at equal env steps spent."""
    scheduler: Literal["none", "asha"] | None = None
    """``asha`` stops poor configurations early: asynchronous successive halving on a configuration's
    seeds together, their mean objective at equal env steps (sweeps/scheduler.py); default none."""
    grace_period: Int(1, MAX_BUDGET) | None = None
    """Env steps before ``asha`` may stop a configuration (its first rung); default the longer of a
    quarter of the budget and the multipliers' warm-up (the plan prints it)."""
    max_concurrent: Int(1, MAX_CPUS) | None = None
    """Trials at once (default: CPUs / cpus_per_trial)."""
    cpus_per_trial: Int(1, MAX_CPUS) | None = None
    """CPUs per trial: as many env runners sample and as many torch threads update; default 1."""
    experiment: Annotated[str, AfterValidator(_display_name)] | None = None
    """The MLflow experiment (default ``lac-sweeps``)."""
    eval_episodes: Int(0, 1000) | None = None
    """Episodes of the evaluation block at the end of every trial, run with the trained policy's
    deterministic action and with its stochastic policy on env seeds no training episode used, logged
    to the trial's run (``eval/<mode>/...``); 0 = none; default 10 (docs/sweeps.md)."""
    eval_modes: list[Annotated[str, StringConstraints(pattern=r"^[a-z_]{1,40}$")]] | None = None
    """The evaluation block's action modes (``lac-eval --actions``): ``generator`` (the deterministic
    action, what ``score: eval`` reads), ``stochastic`` (the policy as it explored) and an
    algorithm's own (LAC's ``langevin``); a trial runs those its algorithm has; default
    [generator, stochastic]."""
    eval_every: Int(1, MAX_BUDGET) | None = None
    """Iterations between evaluation blocks during training (logged at their env steps: an
    evaluation curve); default none: the block at the trial's end only."""
    cost_limits: tuple[NonNegative, ...] | None = Field(None, min_length=1, max_length=MAX_VALUES)
    """A ladder of cost limits b, distinct, each >= 0: every configuration runs at each (a trial per
    configuration × limit × seed, the limit its ``cost_limit``; ``--cost-limits`` on the command line)
    and the report ranks them at each, with the regret to the ``frontier`` where it runs (docs/sweeps.md,
    "Across a ladder of cost limits"); ``lac-sweep calibrate`` proposes one. Default: each task's limit."""
    frontier: Frontier | None = None
    """The fixed-multiplier frontier's runs beside the sweep's own (:class:`Frontier`)."""
    constraints: dict[Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]{1,60}$")], NonNegative] | None = (
        Field(None, min_length=1, max_length=MAX_VALUES))
    """A limit per constraint of the task (``{hazards: 10, vases: 5}``; each task's constraints:
    docs/tasks.md, a user env's its ``constraints``): every trial holds each constraint under its own
    limit with its own multiplier (docs/constraints.md); ``--set constraints.NAME=b`` on the command
    line. Without it, one limit on the summed cost (``cost_limit``, the task's by default)."""
    ladder_constraint: Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.-]{1,60}$")] | None = None
    """With ``constraints`` and ``cost_limits``: the constraint the ladder runs along, each rung of
    ``cost_limits`` its limit, the other constraints at their ``constraints`` limits; the report ranks
    the configurations at each rung on the joint rule, and a ``frontier`` holds that constraint's
    multiplier at each ν while the others learn (docs/constraints.md)."""
    tune: TuneSpec | None = None
    """A tuned comparison (sweeps/tuned.py): every algorithm the sweep runs is searched over its own
    search space with the same searcher, samples, seeds and env steps, its best configuration and its
    default then rerun together on fresh seeds; the report compares default with tuned, and each winner
    is written to the registry of tuned configurations (:class:`TuneSpec`)."""
    preset: Literal["tuned"] | None = None
    """``tuned``: every trial starts from the registry's tuned configuration of its task, algorithm and
    budget (``tuned/<task>/<algo>/``, ``lac-sweep registry`` lists them) instead of the algorithm's
    defaults; refused before Ray starts where the registry has none or its env fingerprint differs."""
    tuned_limit: NonNegative | None = None
    """With ``preset: tuned``: the limit whose registry entry every trial starts from, whatever limit it
    runs at (each rung of ``cost_limits`` too). Default: each trial's own limit; an entry tuned at
    another is refused before Ray starts."""
    score: Literal["eval", "train"] | None = None
    """What every trial is ranked on (sweeps/score.py): ``eval``, the evaluation block's deterministic
    episodes (default; ``train`` when ``eval_episodes`` is 0), or ``train``, the mean over its final
    10% of training iterations; the other is kept beside it in trials.csv and summary.csv."""

    @model_validator(mode="before")
    @classmethod
    def _pbt_form(cls, data):
        # ``search: pbt`` is the algorithm's declared (changeable) space searched by PBT.
        if isinstance(data, dict) and data.get("search") == "pbt":
            if data.get("searcher") not in (None, "pbt"):
                raise KeyedError(("searcher",), f"searcher {data['searcher']} with search: pbt; accepted: "
                                 "searcher pbt (or none)")
            data = {**data, "search": "default", "searcher": "pbt"}
        return data

    @field_validator("task", mode="before")
    @classmethod
    def _one_or_list(cls, v):
        return v if isinstance(v, (list, tuple)) or v is None else [v]

    @field_validator("algo", mode="before")
    @classmethod
    def _algo_forms(cls, v):
        return [_algo_name(a) for a in (v if isinstance(v, (list, tuple)) else [v])]

    @field_validator("seeds", mode="before")
    @classmethod
    def _seeds(cls, v):
        return _seeds_form(v)

    @field_validator("algo")
    @classmethod
    def _algos(cls, v, info: ValidationInfo):
        from lac_rllib.algorithms.registry import algos_text, check_algo

        if not v or len(set(v)) != len(v):
            raise ValueError(f"{excerpt(list(v))}: accepted: {algos_text()} or your own algorithm's module "
                             "(or a list of distinct ones)")
        for i, algo in enumerate(v):  # a user's module is imported and checked here, before Ray starts
            try:
                check_algo(algo, _search_dirs(info))
            except ValueError as e:
                raise KeyedError((i,), str(e)) from None
        return v

    _budget = field_validator("budget", mode="before")(classmethod(lambda cls, v: _budget_value(v)))

    _lists = field_validator("grid")(classmethod(lambda cls, v: v if v is None else _grid_lists(v)))

    _ladder = field_validator("cost_limits")(classmethod(lambda cls, v: _distinct(v)))

    @model_validator(mode="after")
    def _shape(self):
        if self.grace_period is not None and self.scheduler != "asha":
            raise KeyedError(("grace_period",), f"grace_period {self.grace_period} without an early-stopping "
                             "scheduler; accepted: with scheduler: asha")
        if self.eval_episodes == 0 and (self.eval_every is not None or self.eval_modes is not None):
            key = "eval_every" if self.eval_every is not None else "eval_modes"
            raise KeyedError((key,), f"{key} with eval_episodes 0 (no evaluation); accepted: eval_episodes >= 1")
        if self.eval_modes is not None and (not self.eval_modes or len(set(self.eval_modes)) != len(self.eval_modes)):
            raise KeyedError(("eval_modes",), f"{excerpt(self.eval_modes)}: accepted: a non-empty list of distinct "
                             "modes (generator, stochastic, an algorithm's own: LAC's langevin)")
        if self.score == "eval" and self.eval_episodes == 0:
            raise KeyedError(("score",), "score eval ranks on the evaluation block and eval_episodes is 0; "
                             "accepted: eval_episodes >= 1, or score: train")
        if self.grid is not None and self.groups is not None:
            raise KeyedError(("groups",), "give grid or groups, not both (a grid is one group)")
        if self.grid == {} or self.groups == {}:
            raise KeyedError(("grid" if self.grid == {} else "groups",),
                             "an empty grid; accepted: field → a non-empty list of values")
        if (self.cost_limits is not None or self.frontier is not None) and self.search is not None:
            key = "cost_limits" if self.cost_limits is not None else "frontier"
            raise KeyedError((key,), f"{key} with a search: a ladder and a frontier run grid configurations; "
                             "accepted: with grid or groups (or none: one configuration)")
        if self.constraints is not None:
            ladder = self.ladder_constraint is None
            for key, clash in (("cost_limit", "cost_limit" in self.set), ("constraints", "constraints" in self.set),
                               ("cost_limits", ladder and self.cost_limits is not None),
                               ("frontier", ladder and self.frontier is not None)):
                if clash:
                    raise KeyedError(("constraints",), f"constraints with {key}: constraints give each constraint its "
                                     "limit; accepted: constraints alone, or with cost_limits and ladder_constraint "
                                     "(a ladder along one constraint); one limit on the summed cost: cost_limit")
        if self.ladder_constraint is not None and (self.constraints is None or self.cost_limits is None):
            raise KeyedError(("ladder_constraint",), f"ladder_constraint {self.ladder_constraint} without "
                             f"{'constraints' if self.constraints is None else 'cost_limits'}; accepted: with "
                             "constraints (the other constraints' limits) and cost_limits (its rungs)")
        if self.cost_limits is not None and "cost_limit" in self.set:
            raise KeyedError(("set", "cost_limit"), "cost_limit set beside cost_limits; accepted: one of them "
                             "(a ladder of one limit: cost_limits: [b])")
        if self.search == {}:
            raise KeyedError(("search",), "an empty search; accepted: default, or field → a distribution")
        if self.env_steps_budget is not None and (self.search is None or self.searcher == "pbt"):
            raise KeyedError(("env_steps_budget",), "env_steps_budget without a sampling search: it bounds what a "
                             "search's draws spend; accepted: with search and searcher random, tpe, motpe or nsga2 "
                             "(PBT spends members × budget)")
        if self.pbt is not None and self.searcher != "pbt":
            raise KeyedError(("pbt",), f"pbt with searcher {self.searcher or 'unset'}: it configures population-based "
                             "training; accepted: with searcher: pbt (or search: pbt)")
        if self.searcher == "pbt":
            if self.search is None:
                what = "grid" if self.grid is not None else "groups" if self.groups is not None else None
                raise KeyedError((what or "searcher",), f"searcher pbt {'with ' + what if what else 'without a search'}"
                                 ": PBT perturbs fields within search ranges; accepted: search: default (the "
                                 "algorithm's changeable fields) or field → a distribution")
            for key in ("scheduler", "num_samples"):
                if getattr(self, key) not in (None, "none"):
                    raise KeyedError((key,), f"{key} with searcher pbt: the population is pbt.members, ranked and "
                                     "exploited by PBT itself; accepted: pbt: {members: N}, no " + key)
        if self.tune is not None:
            for key in ("search", "cost_limits", "frontier", "preset", "scheduler"):
                if getattr(self, key) not in (None, "none"):
                    raise KeyedError((key,), f"{key} with tune: a tuned comparison searches each algorithm's own "
                                     "space at one limit; accepted: tune with algo (a list) or a grid over algo")
        if self.preset == "tuned" and self.search is not None:
            raise KeyedError(("preset",), "preset tuned with a search: the registry's configurations are points; "
                             "accepted: preset tuned with grid or groups (or neither: one configuration)")
        if self.search is not None:
            if self.grid is not None or self.groups is not None or self.groups_at:
                raise KeyedError(("search",), "give search or grid/groups, not both")
            if self.searcher == "grid":
                raise KeyedError(("searcher",), "searcher grid samples nothing: it runs grid/groups; "
                                                "accepted with search: random | tpe | motpe | nsga2")
            if self.searcher in MULTI_OBJECTIVE and self.scheduler == "asha":
                raise KeyedError(("scheduler",), f"scheduler asha with searcher {self.searcher}: Tune gives a "
                                 "multi-objective search no intermediate results to stop trials by; "
                                 "accepted: scheduler none")
            if self.task is not None and len(self.task) > 1:
                raise KeyedError(("task",), "a search optimises one task; run one sweep per task")
            if len(self.algo) > 1:
                raise KeyedError(("algo",), "a search runs one algorithm; search over it instead: "
                                            "search: {algo: {choice: [...]}}")
        elif self.searcher in ("random", "tpe", *MULTI_OBJECTIVE):
            raise KeyedError(("searcher",), f"searcher {self.searcher} needs a search section (field → distribution)")
        return self

    @property
    def is_search(self) -> bool:
        return self.search is not None

    @property
    def multi_objective(self) -> bool:
        return self.searcher in MULTI_OBJECTIVE

    def seed_list(self) -> tuple[int, ...]:
        return (self.seeds or Seeds(count=3)).values()

    def dump(self) -> str:
        """The sweep as YAML, every key this sweep sets (``sweep.yaml``)."""
        return yaml.safe_dump(to_plain(self.model_dump(exclude_none=True, exclude_defaults=False)),
                              sort_keys=False, width=110)


# ----------------------------------------------------------------------------- loading


class NumbersLoader(yaml.SafeLoader):
    """YAML 1.1 reads ``1e-4`` as a string (it wants ``1.0e-4``): numbers as people write them."""


NumbersLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)[eE][-+]?[0-9]+$|^[-+]?[0-9][0-9_]*\.[0-9_]*$"
               r"|^[-+]?\.(?:inf|Inf|INF)$|^\.(?:nan|NaN|NAN)$"),
    list("-+0123456789."),
)


def builtin_path(space: str) -> Path:
    return BUILTIN_DIR / f"{space}.yaml"


def builtin_spaces() -> tuple[str, ...]:
    return tuple(sorted(p.stem for p in BUILTIN_DIR.glob("*.yaml")))


def load(path: str | Path, text: str | None = None) -> SweepFile:
    """The sweep file at ``path``, checked (both passes); a SweepFileError says what is wrong, where."""
    return load_with_origin(path, text)[0]


def load_with_origin(path: str | Path, text: str | None = None) -> tuple[SweepFile, Origin]:
    """The checked sweep file and where each of its keys is (:class:`Origin`: ``FILE:LINE``)."""
    path = Path(path)
    try:
        data, node = read_yaml(read_yaml_text(path) if text is None else text, NumbersLoader)
    except YamlRefused as e:
        raise SweepFileError(f"{path}{f':{e.line}' if e.line else ''}: {e.message}") from None
    if data is None or data == {}:
        raise SweepFileError(f"{path}: no keys (an empty file); accepted: a mapping of keys (task, algo, grid, ...: "
                             "docs/sweeps.md), e.g. 'task: lac/PointHazard-v0'")
    if not isinstance(data, dict):
        raise SweepFileError(f"{path}: a sweep file is a mapping of keys (task, algo, grid, ...), not a "
                             f"{type(data).__name__}")
    origin = Origin(path, node)
    # A user's module (an env factory's, an algorithm's) is looked up beside the file, then here.
    dirs = tuple(dict.fromkeys((str(path.resolve().parent), os.getcwd())))
    try:
        sweep = SweepFile.model_validate(data, context={"search_dirs": dirs})
    except ValidationError as e:
        raise SweepFileError(first_error(e, origin)) from None
    try:
        check_fields(sweep, dirs)
    except FieldError as e:
        raise SweepFileError(f"{origin(e.loc)}: {e.message}") from None
    return sweep, origin


class Origin:
    """Where a key of a sweep came from, as the first words of an error line about it: the flag
    that set it (``flags``: key path → ``--cpus-per-trial``), else ``FILE:LINE: key.path`` (the
    line of the deepest part of the path the file has), else ``SOURCE: key.path``."""

    def __init__(self, path: Path | None = None, node=None, flags: dict | None = None, source: str = "the sweep"):
        self.path, self.node, self.flags, self.source = path, node, dict(flags or {}), source

    def with_flags(self, flags: dict) -> Origin:
        return Origin(self.path, self.node, {**self.flags, **flags}, self.source)

    def flag(self, loc: tuple) -> str | None:
        """The flag that set ``loc`` (or a key above it), if one did."""
        return next((self.flags[loc[:n]] for n in range(len(loc), 0, -1) if loc[:n] in self.flags), None)

    def __call__(self, loc: tuple) -> str:
        loc = tuple(loc)
        flag = self.flag(loc)
        if flag:
            return flag
        where = _where(self.path, self.node, loc) if self.path else self.source
        return f"{where}: {_dotted(loc)}" if loc else where


#: How pydantic names a union's branch in an error's location (``dict[str,...]``, ``literal['default']``).
_BRANCH = re.compile(r"^(dict|list|tuple|union|literal)\[")


def first_error(e: ValidationError, origin: Origin) -> str:
    """The first of pydantic's errors as one line: where, the key, what is wrong, the value (cut)
    and what is accepted."""
    errors = e.errors()  # an unknown key first: a typo also explains the required key it misses
    # A union (``search: default`` or a mapping) fails in every branch: the branch the value was
    # meant for explains it (a word: the literal's; a mapping: the mapping's).
    meant = [x for x in errors if not (x["type"] == "literal_error" and not isinstance(x.get("input"), str))]
    errors = meant or errors
    err = next((x for x in errors if x["type"] == "extra_forbidden"), errors[0])
    loc = tuple(p for p in err["loc"] if not (isinstance(p, str) and (p.startswith(("<", "function-")) or p == "[key]"
                                                                      or _BRANCH.match(p))))
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, KeyedError):
        loc = (*loc, *cause.loc)
    if err["type"] == "extra_forbidden":
        parent = _model_at(loc[:-1])
        accepted = list(parent.model_fields) if parent else []
        close = difflib.get_close_matches(str(loc[-1]), accepted, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        msg = f"unknown key {excerpt(loc[-1])}{hint}; accepted: {', '.join(accepted)}"
    elif err["type"] in ("value_error", "assertion_error"):
        msg = err["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
    else:  # pydantic's own words say what is accepted; the value is repeated, cut
        got = err.get("input")
        shown = "" if isinstance(got, dict) else f" (got {excerpt(got)})"
        msg = f"{err['msg']}{shown}"
    return f"{origin(loc)}: {msg}"


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The schema model a key path points into (for the accepted keys of an unknown-key error)."""
    inner = {"seeds": Seeds, "task": UserEnv, "groups": Group, "groups_at": GroupsAt, "search": Distribution,
             "tune": TuneSpec}
    mappings = {"groups", "search"}  # field → {name: model}: the next part is a name, not a key
    model, skip = SweepFile, False
    for part in loc:
        if skip or isinstance(part, int):
            skip = False
            continue
        model, skip = inner.get(part, model), part in mappings
    return model


def _dotted(loc: tuple) -> str:
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc).lstrip(".")


def _where(path: Path, node, loc: tuple) -> str:
    """``FILE:LINE`` of the deepest key of ``loc`` the YAML has (a short form such as ``task: X``
    has no list, so the path stops where the file does)."""
    line = None
    for part in loc:
        if isinstance(node, yaml.MappingNode):
            pair = next(((k, v) for k, v in node.value if k.value == str(part)), None)
            if pair is None:
                break
            line, node = pair[0].start_mark.line + 1, pair[1]
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line + 1
        else:
            break
    return f"{path}:{line}" if line else str(path)


def to_plain(v: Any) -> Any:
    """Tuples as lists (YAML), recursively."""
    if isinstance(v, dict):
        return {k: to_plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [to_plain(x) for x in v]
    return v


def to_field_value(v: Any) -> Any:
    """A value from a file as a config field holds it: lists become tuples (layer sizes)."""
    if isinstance(v, (list, tuple)):
        return tuple(to_field_value(x) for x in v)
    return v


# ----------------------------------------------------------------------------- the fields


class FieldError(ValueError):
    def __init__(self, loc: tuple, message: str):
        super().__init__(message)
        self.loc, self.message = loc, message


def check_fields(sweep: SweepFile, search_dirs: tuple[str, ...] = ()) -> None:
    """Every field the sweep sets, sweeps or searches, against the declaration of each algorithm
    that runs it (its docstring'd ``param(..., accepts=...)``): raises FieldError at its key path.
    A user's algorithm named in ``set``, ``grid`` or ``search`` is looked up in ``search_dirs`` too."""
    from lac_rllib.algorithms.registry import ALGO_FIELD

    top_algos = _algos_of(sweep.algo, sweep.set, {}, ("set",), search_dirs)
    if sweep.search is not None:
        algos = top_algos
        if isinstance(sweep.search, dict) and ALGO_FIELD in sweep.search and sweep.search[ALGO_FIELD] != "default":
            algos = _algos_of(top_algos, {}, {ALGO_FIELD: sweep.search[ALGO_FIELD].values_to_check()},
                              ("search",), search_dirs)
        _check_set(sweep.set, algos, ("set",))
        for name, dist in ({} if sweep.search == "default" else sweep.search).items():
            if name != ALGO_FIELD and dist != "default":  # a declared range is the field's own
                for value in dist.values_to_check():
                    check_field(name, value, algos, ("search", name, dist.kind))
        return
    groups = [(("grid",), Group(grid=sweep.grid))] if sweep.grid is not None else []
    groups += [(("groups", g), grp) for g, grp in (sweep.groups or {}).items()]
    groups += [(("groups_at", i, "groups", g), grp) for i, at in enumerate(sweep.groups_at)
               for g, grp in at.groups.items()]
    # Each group's algorithms, checked where they are named (its grid, else its set).
    try:
        group_algos = [_algos_of(top_algos, group.set, group.grid,
                                 _grid_loc(where) if ALGO_FIELD in group.grid else _set_loc(where), search_dirs)
                       for where, group in groups]
    except FieldError as e:
        raise FieldError(e.loc, e.message + _missing_algos_hint(groups, search_dirs)) from None
    # The sweep's set reaches every trial: each algorithm any group runs must have its fields.
    _check_set(sweep.set, tuple(dict.fromkeys(a for algos in group_algos for a in algos)) or top_algos, ("set",))
    for (where, group), algos in zip(groups, group_algos):
        prefix = _grid_loc(where)
        if ALGO_FIELD in group.grid and len(sweep.algo) > 1:
            raise FieldError((*prefix, ALGO_FIELD), f"algo is swept here and the sweep's algo is a list "
                                                    f"{list(sweep.algo)}; give one of them")
        _check_set(group.set, algos, _set_loc(where))
        for i, step in enumerate(group.schedule or ()):
            loc = (*where, "schedule", i, "set")
            _check_set(step.set, algos, loc)
            check_changeable(step.set, algos, loc)
        for name, values in group.grid.items():
            if name != ALGO_FIELD:
                for i, value in enumerate(values):
                    check_field(name, value, algos, (*prefix, name, i))


def _missing_algos_hint(groups: list, search_dirs: tuple[str, ...]) -> str:
    """The tail of a refused algorithm's error: every algorithm the groups name that this install
    lacks (a built-in file such as table2.yaml names baselines before they land), and how to run
    the others meanwhile."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, check_algo

    named = [a for _, g in groups for a in (g.grid.get(ALGO_FIELD) or [g.set.get(ALGO_FIELD)]) if a is not None]
    missing = []
    for algo in dict.fromkeys(named):
        try:
            check_algo(algo, search_dirs)
        except ValueError:
            missing.append(str(algo))
    return (f"; this file names {len(missing)} algorithm(s) not available here ({', '.join(missing)}): run the "
            "others from a copy of it without them (--config COPY.yaml)")


def _grid_loc(where: tuple) -> tuple:
    """The key path of a group's grid (the file's own ``grid`` is its one group's)."""
    return where if where == ("grid",) else (*where, "grid")


def _set_loc(where: tuple) -> tuple:
    """The key path of a group's set (the file's own ``grid`` has the sweep's)."""
    return ("set",) if where == ("grid",) else (*where, "set")


def _algos_of(top: tuple, sets: dict, grid: dict, loc: tuple, search_dirs: tuple[str, ...] = ()
              ) -> tuple[str, ...]:
    """The algorithms a location runs: a swept ``algo``, else a set one, else the sweep's (each
    checked: a name of the registry or a user's module, lac_rllib/algorithms/registry.py)."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, check_algo

    if ALGO_FIELD in grid:
        algos = tuple(grid[ALGO_FIELD])
    elif ALGO_FIELD in sets:
        algos = (sets[ALGO_FIELD],)
    else:
        return tuple(top)
    for i, algo in enumerate(algos):
        try:
            check_algo(algo, search_dirs)
        except ValueError as e:
            where = (*loc, ALGO_FIELD, i) if ALGO_FIELD in grid else (*loc, ALGO_FIELD)
            raise FieldError(where, str(e)) from None
    return algos


def check_changeable(sets: dict, algos: tuple, loc: tuple) -> None:
    """A schedule's fields change mid-run: each must be one its algorithm declares changeable."""
    from lac_rllib.algorithms.registry import algo_config

    for algo in algos:
        changeable = algo_config(algo).changeable_fields()
        for name in sets:
            if name not in changeable:
                raise FieldError((*loc, name), f"{name} is not a field {algo} can change mid-run; accepted in a "
                                 f"schedule: {', '.join(changeable) or 'none'}")


def _check_set(sets: dict, algos: tuple, loc: tuple) -> None:
    from lac_rllib.algorithms.registry import ALGO_FIELD

    for name, value in sets.items():
        if name != ALGO_FIELD:
            check_field(name, value, algos, (*loc, name))


def check_field(name: str, value: Any, algos: tuple, loc: tuple) -> None:
    from lac_rllib.algorithms.registry import ALGOS, algo_config

    for algo in algos:
        fields = algo_config(algo).FIELDS
        if name not in fields.names:
            owners = [a for a in ALGOS if a != algo and name in algo_config(a).FIELDS.names]
            if owners:
                raise FieldError(loc[:loc.index(name) + 1],
                                 f"a field of {' and '.join(owners)}, not of {algo} (which this trial runs); "
                                 f"fields of {algo}: docs/config.md")
            close = difflib.get_close_matches(name, sorted(fields.names), n=3)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise FieldError(loc[:loc.index(name) + 1],
                             f"unknown {algo} field {excerpt(name)}{hint}; accepted: the {len(fields.names)} fields "
                             f"of {algo} in docs/config.md{f' (closest: {chr(44).join(close)})' if close else ''}")
        try:
            fields.check(name, to_field_value(value))
        except ValueError as e:
            raise FieldError(loc, str(e)) from None


# ----------------------------------------------------------------------------- the reference


def reference_markdown() -> str:
    """docs/sweeps.md's "Sweep file reference": every key of every part of the schema, from its
    docstring (test_docs keeps the file in sync: ``python -m sweeps.sweep_file``)."""
    lines = []
    for model in (SweepFile, Group, ScheduleStep, GroupsAt, Seeds, Distribution, UserEnv, Frontier, TuneSpec, PBTSpec):
        lines += [f"#### `{model.__name__}`", "", " ".join((model.__doc__ or "").split()), "",
                  "| key | type | default | what it is |", "|---|---|---|---|"]
        for name, f in model.model_fields.items():
            default = "required" if f.is_required() else "–" if f.default is None else f"`{to_plain(f.default)!r}`"
            kind = _type_text(Annotated[(f.annotation, *f.metadata)] if f.metadata else f.annotation)
            text = " ".join((f.description or "").split())
            cells = [f"`{name}`", kind, default, text]
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _type_text(t: Any) -> str:
    """A field's type as a reader says it: ``list of int >= 0``, ``mapping str → list of any``."""
    import types
    import typing


    origin, args = typing.get_origin(t), typing.get_args(t)
    if origin is Annotated:
        base = _type_text(args[0])
        metas = [m for meta in args[1:] for m in (getattr(meta, "metadata", None) or [meta])]
        found = {type(m).__name__: m for m in metas}

        def bound(name: str) -> str | None:
            v = getattr(found[name], "max_length" if name == "MaxLen" else name.lower()) if name in found else None
            return None if v is None else f"{v:,}" if isinstance(v, int) else str(v)

        low = ("[", bound("Ge")) if "Ge" in found else ("(", bound("Gt")) if "Gt" in found else None
        high = ("]", bound("Le")) if "Le" in found else (")", bound("Lt")) if "Lt" in found else None
        most = f" (at most {bound('MaxLen')})" if "MaxLen" in found else ""
        if low and high:
            return f"{base} in {low[0]}{low[1]}, {high[1]}{high[0]}{most}"
        if low or high:
            op = {"[": ">=", "(": ">", "]": "<=", ")": "<"}[(low or high)[0]]
            return f"{base} {op} {(low or high)[1]}{most}"
        return base + most
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_text(a) for a in args if a is not type(None))
    if origin is Literal:
        return " | ".join(map(str, args))
    if origin is tuple:
        return f"list of {_type_text(args[0])}" if args[-1] is Ellipsis else f"[{', '.join(map(_type_text, args))}]"
    if origin is dict:
        return f"mapping {_type_text(args[0])} → {_type_text(args[1])}"
    if t is Any:
        return "any"
    if t is type(None):
        return "null"
    return getattr(t, "__name__", str(t))


REFERENCE_BEGIN = "<!-- sweep-file reference: generated by `python -m sweeps.sweep_file` -->"
REFERENCE_END = "<!-- end of the sweep-file reference -->"


def write_reference(doc: Path) -> bool:
    """Rewrite the generated part of ``doc``; True if it changed."""
    text = doc.read_text()
    head, _, rest = text.partition(REFERENCE_BEGIN)
    _, _, tail = rest.partition(REFERENCE_END)
    new = f"{head}{REFERENCE_BEGIN}\n\n{reference_markdown()}\n{REFERENCE_END}{tail}"
    doc.write_text(new)
    return new != text


if __name__ == "__main__":
    doc = Path(__file__).parents[1] / "docs" / "sweeps.md"
    print(doc, "updated" if write_reference(doc) else "unchanged")
