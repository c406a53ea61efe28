"""A sweep's plan: what will run, where it goes and what it costs, fixed before Ray starts.

``sweeps/run.py`` makes it in one pass (file and flags → the resolved sweep, sweeps/resolve.py →
its trials → the estimate, sweeps/estimate.py), prints it, and hands it whole to
``sweeps/sweep.py``, which reads nothing else; ``sweep.yaml`` and ``sweep.json`` record it so that
``--resume`` can compare. A confirmation (``--confirm-top``) is planned here too, from the
finished sweep's results.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from lac_rllib.algorithms.registry import DEFAULT_ALGO
from sweeps import spaces, sweep_file
from sweeps.estimate import estimate
from sweeps.infra import Infra, check_optuna_study, default_optuna_storage
from sweeps.record import checked_sweep_dir
from sweeps.resolve import user_algos
from sweeps.spaces import TrialSpec
from sweeps.sweep_file import SweepFile

#: The most trials a sweep may plan unless --max-trials says more: counted before any is built
#: (the plan holds each trial's resolved fields; ~10 ms and a few KB each).
MAX_TRIALS = 5_000


@dataclasses.dataclass(frozen=True)
class Plan:
    sweep: SweepFile  #: the resolved sweep (defaults and flags applied): what every trial comes from
    infra: Infra
    space: str  #: the built-in space, or the sweep file's stem
    tasks: tuple[str, ...]  #: task ids (a user's env registered under its id)
    user_tasks: dict  #: id → a user env's TaskSpec as data (lac_rllib/tasks/user.py), for the trials
    trials: list[TrialSpec] | None  #: the grid's trials; None for a search (Optuna samples them)
    n_trials: int
    concurrency: int  #: trials at once
    sets: dict  #: the fields every trial sets (the sweep's ``set``, and its one algorithm)
    timesteps: int  #: env steps per trial (the largest, where tasks' budgets differ)
    estimated_wall_s: float
    estimated_cpu_h: float
    name: str  #: the sweep's name: its Tune directory under ``storage`` and its MLflow parent run
    storage: str
    optuna_storage: str | None  #: a search's Optuna storage URL
    #: ``--confirm-top``: (K, seeds, budget, by) of the confirmation that follows the sweep
    #: (sweeps/reports/confirm.py; by: ``--confirm-by``, confirm.CONFIRM_BY)
    confirm: tuple | None = None
    #: A confirmation sweep's winners (sweeps/reports/confirm.py ``winners``): its report says whether each held up.
    confirms: tuple | None = None
    #: A user's algorithm (its import path) → the folder its trials import it from (registry.module_dir).
    user_algos: dict = dataclasses.field(default_factory=dict)
    #: Each trial's estimated seconds (a search: the first configuration's, per trial): the wall
    #: time at another concurrency (a cluster's, known once connected) is made from them again.
    trial_seconds: tuple = ()
    #: The evaluation blocks' share of the estimated time (sweeps/estimate.py ``estimate_eval_s``).
    eval_share: float = 0.0
    #: ``scheduler: asha``: (grace period in env steps, why, the rungs) (sweeps/scheduler.py); else None.
    early_stopping: tuple | None = None
    #: (factor, what it came from): this machine's speed against the rates' (sweeps/estimate.py).
    calibration: tuple = (1.0, "the rates as measured")
    #: The env fingerprints its trials run in (id → fingerprint, lac_rllib/tasks/fingerprint.py): a
    #: resume in another environment is refused (sweeps/record.py).
    env_fingerprints: dict = dataclasses.field(default_factory=dict)
    #: ``searcher: pbt``: its sub-populations' exploit intervals in env steps (sweeps/pbt.py); else None.
    pbt: tuple | None = None

    @property
    def task(self) -> str | None:
        """The sweep's one task (None when it runs several)."""
        return self.tasks[0] if len(self.tasks) == 1 else None

    @property
    def budget(self) -> str:
        return str(self.sweep.budget)

    @property
    def seeds(self) -> tuple[int, ...]:
        return self.sweep.seed_list()

    @property
    def experiment(self) -> str:
        return self.sweep.experiment

    @property
    def tracking_uri(self) -> str:
        return self.infra.tracking_uri

    @property
    def swept_algos(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(t.algo for t in self.trials)) if self.trials else ()

    def record(self) -> dict:
        """The plan as JSON-ready data (``sweep.json``, the parent run's plan.json): the trials by label."""
        skip = ("trials", "sweep", "infra", "confirms", "trial_seconds")
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        return out | {"tracking_uri": self.tracking_uri, "budget": self.budget, "seeds": list(self.seeds),
                      "trial_labels": [t.label() for t in self.trials] if self.trials else None}

    def check(self) -> None:
        """Before Ray starts: the sweep's directory is free, or records this sweep where it resumes."""
        checked_sweep_dir(self)

    def run(self, run_plan) -> int:
        """The sweep run by ``run_plan`` (sweeps/run.py's: under its lock, then its confirmation where
        ``--confirm-top`` asks for one): its exit code."""
        return run_plan(self, Path(self.storage) / self.name)


def plan_sweep(sweep: SweepFile, space: str, infra: Infra, search_dirs: tuple[str, ...] = (),
               origin: sweep_file.Origin | None = None, max_trials: int = MAX_TRIALS) -> Plan:
    """A resolved sweep's plan: its tasks (a user's env built and stepped once), its trials with
    their fields resolved, the estimate, its name and storage. ``origin`` says where each key came
    from (a file's line or a flag) for the errors; the trials are counted before any is built."""
    origin = origin or sweep_file.Origin()
    cpus = sweep.cpus_per_trial
    if not infra.address and cpus > (os.cpu_count() or 1):
        # Tune would keep such a trial PENDING forever on the local Ray this command starts.
        raise ValueError(f"{origin(('cpus_per_trial',))} {cpus} is more than this machine's {os.cpu_count()} CPUs; "
                         f"accepted: 1..{os.cpu_count()} (or --address a larger cluster)")
    if sweep.tuned_limit is not None and sweep.preset != "tuned":
        raise ValueError(f"{origin(('tuned_limit',))} {sweep.tuned_limit:g} without preset: tuned (it names the "
                         "limit whose registry entry preset: tuned runs); accepted: with preset: tuned, or no "
                         "tuned_limit")
    tasks, user_tasks = resolve_tasks(sweep, search_dirs, origin)
    seeds = sweep.seed_list()
    pbt = sweep.searcher == "pbt"  # a member per seed (sweeps/pbt.py)
    count = len(seeds) if pbt else sweep.num_samples * len(seeds) if sweep.is_search else spaces.count_trials(
        sweep, tasks)
    if count > max_trials:
        what = "num_samples × seeds" if sweep.is_search else "tasks × configurations × algorithms × seeds"
        raise ValueError(f"{origin(('num_samples',) if sweep.is_search else ())}: the sweep plans {count:,} trials "
                         f"({what}), more than --max-trials {max_trials:,}; accepted: a smaller sweep, or "
                         "--max-trials N where a cluster can run them")
    sets = spaces.trial_sets(sweep)
    if sweep.is_search:  # estimated at the fields it runs before Optuna's samples (the sampled T is not known yet)
        trials, first = None, [dataclasses.replace(spaces.trial_spec(
            {"task": tasks[0], "budget": sweep.budget, "sets": sets, "overrides": {}}), seed=0)]
    else:
        expanded = spaces.expand(sweep, tasks)
        if sweep.preset == "tuned":
            expanded = with_tuned(expanded, sweep, sets, infra.registry)
        trials = first = spaces.resolve_trials(expanded, sweep.budget, sets)
    from lac_rllib.constrained.cpus import check_cpus

    for t in first:
        check_cpus(t.params.get("num_envs_per_env_runner", 1), cpus, origin(("cpus_per_trial",)))
    # search: each sampled configuration is trained with every seed (sweeps/sweep.py, SeedRepeater)
    n_trials = len(trials) if trials is not None else len(seeds) if pbt else sweep.num_samples * len(seeds)
    concurrency = min(sweep.max_concurrent or max(1, (os.cpu_count() or 1) // cpus), n_trials)
    figures = estimate(trials or first * n_trials, sweep, cpus, concurrency, infra.tracking_uri)
    timesteps = max(t.timesteps for t in first)
    if sweep.eval_modes:  # each mode must be one some algorithm of the sweep acts in
        from lac_rllib.algorithms.registry import actions

        accepted = ["generator", "stochastic", *dict.fromkeys(
            m for a in dict.fromkeys(t.algo for t in trials or first) for m in actions(a))]
        for i, mode in enumerate(sweep.eval_modes):
            if mode not in accepted:
                raise ValueError(f"{origin(('eval_modes', i))}: {mode!r}; accepted with this sweep's algorithms: "
                                 f"{', '.join(dict.fromkeys(accepted))}")
    early = None
    if sweep.scheduler == "asha":  # per configuration, from the multipliers' warm-up (sweeps/scheduler.py)
        from sweeps.scheduler import grace_period, milestones

        grace, why = grace_period(trials or first, timesteps, sweep.grace_period)
        early = (grace, why, tuple(milestones(grace, timesteps)))
    population = check_pbt(sweep, first[0], timesteps, origin) if pbt else None
    if sweep.env_steps_budget is not None and sweep.env_steps_budget < len(seeds) * timesteps:
        raise ValueError(f"{origin(('env_steps_budget',))} {sweep.env_steps_budget:,} is less than one configuration "
                         f"costs ({len(seeds)} seeds × {timesteps:,} env steps); accepted: at least "
                         f"{len(seeds) * timesteps:,}")
    name = sweep.name
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id

    # A search's samples may change a field the fingerprint reads: its base configuration stands for them.
    fps = [fingerprint(t.task, t.params) for t in first]
    env_fingerprints = {fingerprint_id(fp): fp for fp in fps}
    optuna_storage = None
    if sweep.is_search and not pbt:
        optuna_storage = infra.optuna_storage or default_optuna_storage(infra.tracking_uri, infra.storage)
        check_optuna_study(optuna_storage, name, infra.resume)
    return Plan(
        sweep=sweep, infra=infra, space=space, tasks=tuple(tasks), user_tasks=user_tasks, trials=trials,
        n_trials=n_trials, concurrency=concurrency, sets=sets, timesteps=timesteps, early_stopping=early,
        estimated_wall_s=figures.wall_s, estimated_cpu_h=figures.cpu_h,
        trial_seconds=figures.trial_seconds, eval_share=figures.eval_share, calibration=figures.calibration,
        name=name, storage=str(Path(infra.storage.removeprefix("file://")).resolve()), optuna_storage=optuna_storage,
        user_algos=user_algos(sweep), env_fingerprints=env_fingerprints, pbt=population,
    )


def check_pbt(sweep: SweepFile, first: TrialSpec, timesteps: int, origin) -> tuple[int, ...]:
    """``searcher: pbt`` checked before Ray starts; returns its sub-populations' intervals (env
    steps, fastest first): each shorter than the budget, at least two members per sub-population,
    the replay buffer kept in checkpoints (an exploit copies it with the learner)."""
    spec = sweep.pbt
    intervals = spec.intervals(timesteps)
    if max(intervals) >= timesteps:
        raise ValueError(f"{origin(('pbt', 'interval'))} {max(intervals):,} env steps is not shorter than the budget "
                         f"({timesteps:,} env steps): no member would ever exploit; accepted: 1..{timesteps - 1:,}")
    if spec.members < 2 * len(intervals):
        raise ValueError(f"{origin(('pbt', 'members'))} {spec.members} for {len(intervals)} sub-populations: each "
                         f"needs two members to rank; accepted: members >= {2 * len(intervals)}")
    if first.params.get("store_replay_buffer") is False:
        raise ValueError(f"{origin(('set', 'store_replay_buffer'))} false with searcher pbt: an exploit copies the "
                         "donor's whole state, its replay buffer included; accepted: store_replay_buffer true")
    return intervals


def with_tuned(trials: list[TrialSpec], sweep: SweepFile, sets: dict, registry: str | None) -> list[TrialSpec]:
    """``preset: tuned``: each trial (the frontier's aside) starts from its task's and algorithm's entry
    in the registry of tuned configurations, below the sweep's ``set`` and its own swept values. The
    entry is chosen and checked per trial, after its group's and grid's fields: tuned at the sweep's
    budget, at the trial's limit (each rung of a ladder its own; the sweep file's ``tuned_limit``
    names another explicitly) and in the environment the trial has with the entry applied. Refused
    in one line where there is none (sweeps/tuned_registry.py ``tuned_entry``); an entry whose
    verdict is that the default stands starts its trials from the default, said in one line."""
    import json

    from lac_rllib.algorithms.registry import ALGO_FIELD
    from lac_rllib.tasks import get_task
    from lac_rllib.tasks.fingerprint import fingerprint
    from sweeps.tuned_registry import DEFAULT_REGISTRY, DEFAULT_STANDS, applied, applied_schedule, tuned_entry

    registry = Path(registry or DEFAULT_REGISTRY)
    cache, said, out = {}, set(), []
    for t in trials:
        if t.group == spaces.FRONTIER_GROUP:
            out.append(t)
            continue
        algo = t.overrides.get(ALGO_FIELD, sets.get(ALGO_FIELD, DEFAULT_ALGO))
        key = (t.task, json.dumps(t.overrides, sort_keys=True, default=str))  # its seeds share the configuration
        if key not in cache:
            own = spaces.trial_params(t.task, sweep.budget, sets, t.overrides)
            limit = own.get(spaces.COST_LIMIT_FIELD)
            limit = get_task(t.task).cost_limit if limit is None else limit

            def environment(config: dict, t=t) -> dict:  # the trial's fingerprint with an entry's fields under it
                tuned = {k: v for k, v in config.items() if k not in t.overrides and k not in sets}
                return fingerprint(t.task, spaces.trial_params(t.task, sweep.budget, sets, {**tuned, **t.overrides}))

            # a limit per constraint (constraints): an entry tuned at those limits
            wanted = own["constraints"] if own.get("constraints") else float(limit)
            path, entry = tuned_entry(registry, t.task, algo, sweep.budget, wanted, environment,
                                      dataclasses.replace(t, params=own).config_label(), sweep.tuned_limit)
            cache[key] = ({k: v for k, v in applied(entry).items() if k not in t.overrides and k not in sets},
                          applied_schedule(entry))
            if entry.verdict == DEFAULT_STANDS and path not in said:
                said.add(path)
                print(f"preset: tuned: {path}: tuning {algo} on {t.task} at budget {entry.budget}, limit "
                      f"{entry.cost_limit:g} did not beat its default on fresh seeds (verdict {DEFAULT_STANDS}): "
                      "its trials run the default", flush=True)
        fields, schedule = cache[key]  # a PBT winner's schedule replayed, the trial's own fields above it
        own = {**sets, **t.overrides}
        out.append(dataclasses.replace(t, overrides={**fields, **t.overrides}, schedule=t.schedule or (
            schedule and [[at, {k: v for k, v in f.items() if k not in own}] for at, f in schedule])))
    return out


def resolve_tasks(sweep: SweepFile, search_dirs: tuple[str, ...] = (), origin: sweep_file.Origin | None = None
                  ) -> tuple[list[str], dict]:
    """The sweep's task ids, every one known here; a user's env is built once and stepped first
    (lac_rllib/tasks/user.py), its definition returned to travel with the trials."""
    from lac_rllib.tasks import get_task
    from lac_rllib.tasks.user import definition, user_task

    origin = origin or sweep_file.Origin()
    ids, user = [], {}
    for i, task in enumerate(sweep.task):
        if isinstance(task, str):
            try:
                get_task(task)  # unknown id -> ValueError naming the closest known ones
            except ValueError as e:
                raise ValueError(f"{origin(('task', i))}: {e}") from None
            ids.append(task)
            continue
        try:
            spec = user_task(task.task_id(), factory=task.factory, gym_id=task.id, cost_limit=task.cost_limit,
                             episode_cost_discount=task.episode_cost_discount, cost_key=task.cost_key,
                             preset=task.preset, kwargs=task.kwargs, search_dirs=search_dirs,
                             constraints=task.constraints)
        except ValueError as e:
            raise ValueError(f"{origin(('task', i))}: {e}") from None
        ids.append(spec.id)
        user[spec.id] = definition(spec)
    return ids, user


def check_confirm(plan: Plan, top: int, seeds: int | None, budget: str | int | None, by: str = "return"
                  ) -> tuple[int, int, str | int, str]:
    """``--confirm-top K [--confirm-seeds N] [--confirm-budget B] [--confirm-by BY]`` checked before
    Ray starts: one task, a budget at least the sweep's (a smaller one would confirm something
    else), and a regret choice only where the sweep has a ladder and its frontier (the regret is
    R*(b) − R(b) against it). Returns the plan's ``confirm``: (K, seeds, budget, by), the defaults
    filled in."""
    from sweeps.reports.confirm import BY_RETURN, CONFIRM_BY

    if by not in CONFIRM_BY:
        raise ValueError(f"--confirm-by {by}; accepted: {' | '.join(CONFIRM_BY)}")
    ladder, frontier = len(plan.sweep.cost_limits or ()) > 1, bool(plan.sweep.frontier)
    if by != BY_RETURN and not (ladder and frontier):
        missing = " and ".join(k for k, ok in (("cost_limits (two limits or more)", ladder), ("frontier", frontier))
                               if not ok)
        raise ValueError(f"--confirm-by {by}: the regret over a ladder needs the sweep's {missing} "
                         f"(R*(b) comes from the fixed-multiplier frontier); accepted: --confirm-by {BY_RETURN}, "
                         "or a sweep file with cost_limits and frontier")
    from sweeps.reports.verdicts import MIN_FRONTIER_SEEDS

    if by != BY_RETURN and len(plan.seeds) < MIN_FRONTIER_SEEDS:
        raise ValueError(f"--confirm-by {by} with {len(plan.seeds)} seed(s): R*(b) chooses the frontier's ν on some "
                         f"seeds and measures it on others; accepted: --seeds {MIN_FRONTIER_SEEDS} or more")
    if len(plan.tasks) != 1:
        raise ValueError(f"--confirm-top with {len(plan.tasks)} tasks: a confirmation reruns one task's winners; "
                         "accepted: a sweep of one task")
    budget = budget if budget is not None else plan.sweep.budget
    steps = spaces.get_budget(budget).for_task(plan.tasks[0])
    if steps < plan.timesteps:
        raise ValueError(f"--confirm-budget {budget}: {steps:,} env steps is less than the sweep's {plan.timesteps:,}; "
                         "accepted: the same or a larger budget")
    return top, seeds or max(len(plan.seeds), 3), budget, by


def confirmation_plan(plan: Plan) -> Plan | None:
    """``--confirm-top``: the plan of the confirmation that follows the finished sweep ``plan``: its
    K best feasible configurations (or least regret over a ladder) beside the default and the
    baselines the sweep ran, on fresh seeds, as the sweep NAME-confirm (sweeps/followup.py
    ``confirm_top``). None: no feasible configuration but the default."""
    from sweeps.followup import CONFIRM, confirm_top, confirmation_infra

    found = confirm_top(plan)
    if found is None:
        return None
    cfile, top = found
    infra = confirmation_infra(plan.infra, plan.storage, cfile.name)
    return dataclasses.replace(plan_sweep(cfile, CONFIRM, infra), confirms=tuple(top))
