"""From a sweep (sweeps/sweep_file.py) to its trials: budgets, the expansion of a grid into
:class:`TrialSpec`s, a search's Tune distributions, and the one place a trial's fields are resolved
(:func:`trial_params`).

A grid sweep expands to a list of :class:`TrialSpec` (:func:`expand`); a search to Tune
distributions that Optuna samples (:func:`tune_search_space`). Each trial is one run of one
algorithm (``algo``: LAC or a
baseline, lac_rllib/algorithms/registry.py): a task, a seed and the algorithm's field overrides.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.algorithms.registry import DEFAULT_ALGO  # no RLlib import: the registry imports lazily

#: The field a ladder sets per trial, and the frontier's group and field (sweeps/reports/ladder.py).
COST_LIMIT_FIELD, FRONTIER_GROUP, FRONTIER_FIELD = "cost_limit", "frontier", "nu_fixed"
REPEAT_INDEX = "__trial_index__"  # ray.tune.search.repeater.TRIAL_INDEX (not imported: no Ray before the plan)
#: How a trial is labelled, carried in its Tune config (sweeps/sweep.py ``param_space``): its
#: algorithm first and once. A config without it was planned when LAC's trials named no algorithm
#: and others' named theirs, sometimes twice: a sweep recorded then and resumed keeps those labels
#: (:func:`legacy_config_label`), one per configuration across its trials before and after.
LABELS_KEY, LABELS = "labels", "algorithm-first"
DEFAULT_TASK = "lac/PointHazard-v0"  # a sweep file that names no task: a task that learns in minutes
QUICK_TINY_STEPS = 40_000


@dataclasses.dataclass(frozen=True)
class Budget:
    """Env steps per trial, per task preset (``"*"``: any other preset), and the budget's ``name``:
    every algorithm gets the same env steps, and at a named budget each algorithm sets the fields
    it declares for it (``BUDGET_FIELDS`` on its config class: :func:`trial_params` reads them)."""

    steps: dict
    doc: str
    name: str | None = None  #: smoke | quick | paper; None: a number of env steps (the presets' own fields)

    def for_task(self, task: str) -> int:
        """Env steps per trial on ``task`` (its preset's)."""
        from lac_rllib.tasks import get_task

        return self.steps.get(get_task(task).preset, self.steps["*"])

    def describe(self) -> str:
        steps = ", ".join(f"{n:,}" + ("" if p == "*" else f" on {p} tasks") for p, n in self.steps.items())
        return f"{steps} env steps: {self.doc}"


# The default ablation (python sweeps/run.py --space ablation) runs on the tiny task, where
# QUICK_TINY_STEPS of the tiny preset learn, on a reduced Table 3 grid (sweeps/builtin/ablation.yaml);
# calibrated by running it (docs/sweeps.md). On the paper's tasks 16k steps are a machinery check:
# the paper's 2.5M cannot be shrunk that far. What each algorithm sets at each budget is declared
# in its folder (BUDGET_FIELDS).
BUDGETS: dict[str, Budget] = {
    "smoke": Budget({"*": 2_000}, "seconds per trial: proves the machinery, learns nothing", "smoke"),
    "quick": Budget({"tiny": QUICK_TINY_STEPS, "*": 16_000},
                    "the default ablation learns lac/PointHazard-v0 in 11-15 min on 2 cores; on the paper's tasks "
                    "a machinery check that learns nothing", "quick"),
    "paper": Budget({"*": 2_500_000}, "the paper's 2.5M env steps with the docs/spec.md §5 presets", "paper"),
}


def get_budget(budget: str | int) -> Budget:
    """A named budget (``BUDGETS``) or a number of env steps (with the presets' own fields)."""
    if isinstance(budget, int) and not isinstance(budget, bool):
        return Budget({"*": budget}, "env steps with each algorithm's preset fields")
    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; accepted: {' | '.join(BUDGETS)} or a number of env steps")
    return BUDGETS[budget]


@dataclasses.dataclass(frozen=True)
class TrialSpec:
    """One point of a grid: which group it belongs to and what it sets."""

    group: str
    param: str
    value: Any
    task: str
    seed: int
    overrides: dict
    #: Test hook: the trial raises at this iteration (exercises the failure path end to end).
    fail_at_iteration: int | None = None
    #: The trial runs LAC's defaults (for its task and budget): the baseline of the report's comparisons.
    default: bool = False
    #: A search trial's values as Optuna sampled them (its name); None for grid trials.
    sampled: dict | None = None
    #: ``algo`` and every field of that algorithm in this trial, as :func:`trial_params` resolves
    #: them (at plan time for a grid trial, in the trial for a search sample); what the estimate,
    #: the trainable and the default flag read. None until resolved.
    params: dict | None = None
    #: Env steps of this trial (its budget on its task, for its algorithm). None until resolved.
    timesteps: int | None = None
    #: The cost limit of the ladder this trial runs at (``cost_limits``; its ``cost_limit``); None:
    #: no ladder, the task's limit.
    limit: float | None = None
    #: Labelled as a sweep recorded before ``LABELS`` labelled it (its Tune config lacks ``LABELS_KEY``).
    legacy_label: bool = False
    #: A schedule its changeable fields follow, [[env steps, {field: value}], ...] (a group's
    #: ``schedule``: a PBT winner's replayed, sweeps/pbt.py); None: its fields fixed.
    schedule: list | None = None

    @property
    def algo(self) -> str:
        """The trial's algorithm (lac_rllib/algorithms/registry.py)."""
        from lac_rllib.algorithms.registry import ALGO_FIELD, DEFAULT_ALGO

        return (self.params or self.overrides).get(ALGO_FIELD, DEFAULT_ALGO)

    def config_label(self) -> str:
        """The configuration without its seed (MLflow's ``lac.config`` tag), e.g.
        ``ppo_lag-ladder-PointHazard-v0-b2``: its algorithm, first and once for every algorithm, then
        its group without the algorithm's name, its grid point without ``algo`` (or its sampled
        values), its task and its rung of a ladder. A label names; no trial's learning reads it."""
        if self.legacy_label:
            return legacy_config_label(self)
        from lac_rllib.algorithms.registry import ALGO_FIELD

        algo = self.algo
        if self.sampled is not None:
            return f"{algo}-{search_label({k: v for k, v in self.sampled.items() if k != ALGO_FIELD}, None)}"
        group = "-".join(part for part in self.group.split("-") if part != algo)  # ALGO-tuned1, baseline-ALGO
        label = "-".join(p for p in (algo, group, _grid_point(self.param, self.value), self.task.split("/")[-1]) if p)
        return label if self.limit is None else f"{label}-b{_short(self.limit)}"  # a ladder's rung: its own

    def label(self) -> str:
        return f"{self.config_label()}-s{self.seed}"


def legacy_config_label(t: TrialSpec) -> str:
    """A trial's label as sweeps recorded before ``LABELS`` wrote it: LAC's without its algorithm,
    another algorithm's with it first, a grid over ``algo`` with it as the swept value, a search's
    by its sampled values alone."""
    if t.sampled is not None:
        return search_label(t.sampled, None)
    task = t.task.split("/")[-1]
    label = f"{t.group}-{t.param}={t.value}-{task}" if t.param else f"{t.group}-{task}"
    label += "" if t.limit is None else f"-b{_short(t.limit)}"
    return label if t.algo == DEFAULT_ALGO or t.param == "algo" else f"{t.algo}-{label}"


def _grid_point(param: str, value) -> str:
    """A grid point in a label, ``param=value``, without ``algo`` (the label names it first)."""
    from lac_rllib.algorithms.registry import ALGO_FIELD

    fields = param.split(",") if param else []
    if ALGO_FIELD not in fields:
        return f"{param}={value}" if param else ""
    values = str(value).split(",") if len(fields) > 1 else [value]
    kept = [(f, v) for f, v in zip(fields, values) if f != ALGO_FIELD]
    return f"{','.join(f for f, _ in kept)}={','.join(str(v) for _, v in kept)}" if kept else ""


def config_id(task: str, timesteps: int, params: dict) -> str:
    """A stable id of a configuration without its seed: what it learns with (task, budget, every
    LAC field except the speed-only ones). Equal across seeds, different between configurations."""
    import hashlib
    import json

    speed = speed_fields(params)
    what = {"task": task, "timesteps": int(timesteps), **{k: v for k, v in params.items() if k not in speed}}
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:12]


def speed_fields(params: dict) -> frozenset:
    """The speed-only fields of the algorithm ``params`` names (``algo``; LAC without one)."""
    from lac_rllib.algorithms import registry

    return registry.speed_fields(params.get(registry.ALGO_FIELD, registry.DEFAULT_ALGO))


# Short names of the searched fields in a search trial's label (ASCII: labels name Tune's trials).
SEARCH_LABEL = {"langevin_steps": "T", "langevin_step_size": "eta", "temperature": "lam", "beta": "beta"}


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.1e}" if v and abs(v) < 1e-2 else f"{v:.3g}"
    return str(v)


def search_label(overrides: dict, seed: int | None) -> str:
    """A search trial's label from its sampled values, e.g. ``search-T=37-eta=2.1e-04-lam=3.0e-03-beta=4.2-s0``
    (without ``-s0`` when ``seed`` is None: the configuration)."""
    parts = [f"{SEARCH_LABEL.get(name, name)}={_short(v)}" for name, v in overrides.items() if v is not None]
    return "-".join(["search", *parts, *([] if seed is None else [f"s{seed}"])])


def trial_spec(config: dict) -> TrialSpec:
    """A Tune trial's config as the TrialSpec it runs: a grid trial carries its own, resolved at
    plan time (``trial``); a search trial is made from what Optuna sampled (``overrides``), resolved
    here through the same :func:`trial_params` (with the sweep's ``budget`` and ``sets``), its seed
    the sweep's seed at its index among its sample's repeats (Tune's Repeater numbers them 0..N-1);
    labelled the legacy way where the config lacks ``LABELS_KEY`` (a sweep planned before it)."""
    legacy = config.get(LABELS_KEY) != LABELS
    if "trial" in config:
        return dataclasses.replace(TrialSpec(**config["trial"]), legacy_label=legacy)
    task, budget, sets = config["task"], config["budget"], config.get("sets", {})
    sampled = dict(config["overrides"])
    params = trial_params(task, budget, sets, sampled)
    index = int(config.get(REPEAT_INDEX, 0))
    seed = config["seeds"][index] if "seeds" in config else index
    return TrialSpec("search", "", None, task, seed, sampled, sampled=sampled, params=params,
                     default=params == trial_params(task, budget, sets), timesteps=get_budget(budget).for_task(task),
                     legacy_label=legacy)


def groups_for(sweep, preset: str) -> dict:
    """The sweep file's groups for a task of ``preset`` at the sweep's budget: the first matching
    ``groups_at``, else ``groups``, else its ``grid`` as one group, else one configuration (a
    resolved sweep always has ``groups``: sweeps/resolve.py names a file's one group after the file)."""
    from sweeps.sweep_file import Group

    for at in sweep.groups_at:
        if (at.budget is None or str(at.budget) == str(sweep.budget)) and at.preset in (None, preset):
            return at.groups
    if sweep.groups is not None:
        return sweep.groups
    return {sweep.name or "sweep": Group(grid=sweep.grid or {})}


def count_trials(sweep, task_ids: list[str]) -> int:
    """How many trials :func:`expand` would build, counted without building them (a sweep file
    can ask for more than memory holds: sweeps/plan.py refuses it first)."""
    import math

    from lac_rllib.tasks import get_task

    seeds, limits = len(sweep.seed_list()), len(sweep.cost_limits or (None,))
    per_config = len(sweep.algo if len(sweep.algo) > 1 else (None,)) * limits * seeds
    frontier = len(sweep.frontier.nu) * seeds if sweep.frontier else 0
    return sum(math.prod(len(v) for v in group.grid.values()) * per_config
               for task in task_ids for group in groups_for(sweep, get_task(task).preset).values()
               ) + frontier * len(task_ids)


def expand(sweep, task_ids: list[str]) -> list[TrialSpec]:
    """A grid sweep's trials, in order: task, group, configuration (grid combinations, the file's
    order), algorithm (where ``algo`` is a list), cost limit (where ``cost_limits`` is a ladder:
    its ``cost_limit``, or along ``ladder_constraint`` that constraint's limit), seed; then the task's
    fixed-multiplier frontier (``frontier``: group ``frontier``, one configuration per fixed ν, at the
    task's limit: ν does not follow it). A
    configuration's ``overrides`` are its group's ``set`` under its grid values; ``param``/``value``
    name what its grid point sweeps."""
    import itertools

    from lac_rllib.tasks import get_task
    from sweeps.sweep_file import to_field_value

    algos = sweep.algo if len(sweep.algo) > 1 else (None,)
    trials = []
    for task in task_ids:
        for name, group in groups_for(sweep, get_task(task).preset).items():
            fields = list(group.grid)
            for combo in itertools.product(*group.grid.values()):
                point = {f: to_field_value(v) for f, v in zip(fields, combo)}
                param = ",".join(fields)
                value = (point[fields[0]] if len(fields) == 1 else ",".join(_short(v) for v in point.values())
                         ) if fields else None
                for algo in algos:
                    overrides = {**{k: to_field_value(v) for k, v in group.set.items()}, **point,
                                 **({"algo": algo} if algo else {})}
                    for limit in sweep.cost_limits or (None,):
                        own = overrides if limit is None else {**overrides, COST_LIMIT_FIELD: float(limit)}
                        if limit is not None and sweep.ladder_constraint:  # a rung along one constraint
                            rung = {**{k: float(v) for k, v in sweep.constraints.items()},
                                    sweep.ladder_constraint: float(limit)}
                            own = {**overrides, "constraints": rung}
                        schedule = ([[int(e.at), {k: to_field_value(v) for k, v in e.set.items()}]
                                     for e in group.schedule] if group.schedule else None)
                        trials += [TrialSpec(name, param, value, task, seed, own, limit=limit, schedule=schedule)
                                   for seed in sweep.seed_list()]
        if sweep.frontier:
            along = {}
            if sweep.ladder_constraint:  # along one of several constraints: its ν held, the others learn
                along = {"nu_fixed_constraint": sweep.ladder_constraint,
                         "constraints": {**{k: float(v) for k, v in sweep.constraints.items()},
                                         sweep.ladder_constraint: float(max(sweep.cost_limits))}}
            for nu in sweep.frontier.nu:
                overrides = {"algo": sweep.frontier.algo, FRONTIER_FIELD: float(nu), **along}
                trials += [TrialSpec(FRONTIER_GROUP, FRONTIER_FIELD, float(nu), task, seed, overrides)
                           for seed in sweep.seed_list()]
    return trials


def declared_search(algo: str, task: str, budget, sets: dict, search, changeable: bool = False) -> dict:
    """A search's ``default`` entries as distributions (a sweep file's data): ``search: default`` is
    ``algo``'s whole declared space (lac_rllib/constrained/search_space.py), a field whose value is
    ``default`` that field's declared range; ranges ``around`` a default are placed around the field's
    value on ``task`` at ``budget`` with ``sets``. Other entries are kept as given. ``changeable``:
    the fields PBT may change mid-run instead (``CHANGEABLE``, with their ranges)."""
    from lac_rllib.algorithms.registry import changeable_space, search_space

    declared = changeable_space(algo) if changeable else search_space(algo)
    if not declared:
        raise ValueError(f"search: default: {algo} declares no search space; accepted: field → a distribution")
    wanted = dict.fromkeys(declared, "default") if search == "default" else dict(search)
    unknown = [f for f, d in wanted.items() if d == "default" and f not in declared]
    if unknown:
        raise ValueError(f"search.{unknown[0]}: default, and {unknown[0]} is not in {algo}'s search space; "
                         f"accepted: {', '.join(declared)} (or a distribution of your own)")
    base = trial_params(task, budget, {**sets, "algo": algo})
    out = {}
    for name, dist in wanted.items():
        if dist != "default":
            out[name] = dist.model_dump(exclude_none=True) if hasattr(dist, "model_dump") else dist
            continue
        d = declared[name]
        args = list(d.bounds(base.get(name)))
        out[name] = {d.kind: [int(a) for a in args] if d.kind == "int" else args}
    return out


def tune_search_space(search: dict) -> dict:
    """A search file's distributions as Tune's (OptunaSearch converts them to Optuna's)."""
    from ray import tune

    kinds = {"choice": lambda *c: tune.choice(list(c)), "uniform": tune.uniform, "loguniform": tune.loguniform,
             "int": lambda lo, hi: tune.randint(lo, hi + 1), "quniform": tune.quniform}
    return {name: kinds[d.kind](*d.args) for name, d in search.items()}


def trial_sets(sweep) -> dict:
    """What every trial sets: the sweep's ``set`` and ``constraints``, and its algorithm when it runs one
    baseline."""
    from lac_rllib.algorithms.registry import ALGO_FIELD
    from sweeps.sweep_file import to_field_value

    sets = {k: to_field_value(v) for k, v in sweep.set.items()}
    if sweep.constraints is not None:  # a limit per constraint: the field every algorithm has
        sets["constraints"] = {name: float(b) for name, b in sweep.constraints.items()}
    if len(sweep.algo) == 1 and sweep.algo[0] != DEFAULT_ALGO:
        sets[ALGO_FIELD] = sweep.algo[0]
    return sets


def trial_params(task: str, budget: str, sets: dict, overrides: dict | None = None) -> dict[str, Any]:
    """``algo`` and every field of that algorithm in a trial of ``task`` at ``budget``: the one place
    the precedence is written. The algorithm is the trial's ``algo`` override, else ``--set algo=``,
    else the default algorithm. Then the algorithm's preset for the task < its overrides for the
    task's family (``TASK_FAMILY_OVERRIDES``, e.g. LAC's T = 50 on the Button tasks) < the fields it
    declares for a named budget (``BUDGET_FIELDS``) < the user's ``--set`` < the trial's own
    ``overrides`` (the swept or sampled value).
    ``build_config`` applies the first two (``SafeTaskConfig.task``); the horizon of the
    learning-rate decay is the budget's env steps unless an override names another."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, budget_fields, build_config, split_algo
    from lac_rllib.tasks import get_task

    named = get_budget(budget)
    steps, preset = named.for_task(task), get_task(task).preset
    algo, fields = split_algo({**sets, **(overrides or {})})
    declared = budget_fields(algo, named.name, preset) if named.name else {}
    config = build_config(algo, task, 0, {**declared, **fields}, timesteps=steps)
    return {ALGO_FIELD: algo, **config.params()}


def resolve_trials(trials: list[TrialSpec], budget: str, sets: dict) -> list[TrialSpec]:
    """The grid's trials with their LAC fields resolved (:func:`trial_params`), and the default flag on
    those whose overrides change nothing: they run LAC's defaults (for their task, at this budget,
    with the user's --set), the baseline every configuration is compared with."""
    base, out = {}, []
    for t in trials:
        if t.task not in base:
            base[t.task] = trial_params(t.task, budget, sets)
        params = trial_params(t.task, budget, sets, t.overrides)
        out.append(dataclasses.replace(t, params=params, default=params == base[t.task] and not t.schedule,
                                       timesteps=get_budget(budget).for_task(t.task)))
    return out
