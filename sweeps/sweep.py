"""Running a planned sweep on Ray Tune and closing it in MLflow (called by ``sweeps/run.py``)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import platform
import signal
import sys
from pathlib import Path

import optuna
import ray
from ray import tune
from ray.tune.search import Repeater, Searcher
from ray.tune.search.optuna import OptunaSearch

from lac_rllib.constrained.cpus import run_resources
from lac_rllib.constrained.metrics import COST_LIMIT, ENV_STEPS, EPISODE_COST, EPISODE_RETURN
from sweeps import spaces
from sweeps.estimate import duration_text, estimate_wall_s
from sweeps.live_table import LiveTable
from sweeps.objective import CONSTRAINT, OBJECTIVE, objective
from sweeps.plan import Plan
from sweeps.record import SWEEP_FILE, SWEEP_YAML, write_record
from sweeps.reports.results import close_sweep
from sweeps.scheduler import ConfigurationASHA
from sweeps.score import SCORE_COST, SCORE_RETURN, SCORES
from sweeps.search import SPENT, PicklableNSGAIISampler, make_sampler  # noqa: F401 (a resumed NSGA-II sweep's pickle)
from sweeps.tracking import (
    STATUS_TAG,
    STOPPED_TAG,
    SweepTracker,
)
from sweeps.trainable import EVAL_EPISODES, SweepTrial

METRIC, MODE = OBJECTIVE, "max"
MULTI_OBJECTIVES = (EPISODE_RETURN, EPISODE_COST)  # a multi-objective search's, maximised and minimised


class ConstrainedOptunaSearch(OptunaSearch):
    """OptunaSearch that hands each trial's constraint value (episode cost − limit, ≤ 0 is
    feasible) to Optuna, whose TPE sampler reads it (Tune's class never does: docs/dependencies.md,
    "Optuna constraints")."""

    def on_trial_complete(self, trial_id, result=None, error=False):
        ot_trial = self._ot_trials.get(trial_id)
        constraint = (result or {}).get(CONSTRAINT)
        # NaN until an episode completes after a (re)start: Optuna refuses it, and raising here
        # would kill Tune's controller. A trial without a constraint value is one Optuna's TPE
        # ranks below those with one, which is what an unmeasured cost deserves.
        if ot_trial is not None and constraint is not None and math.isfinite(constraint):
            ot_trial.set_constraint("episode_cost_minus_limit", float(constraint))
        super().on_trial_complete(trial_id, result=result, error=error)


class EnvStepBudget(Searcher):
    """A search that stops drawing configurations at a budget of env steps spent (the sweep file's
    ``env_steps_budget``): a configuration is drawn only while what finished configurations spent,
    plus ``per_configuration`` for each one still running and for the new one, stays within
    ``budget``. A running configuration counts at its full cost until it ends, so the budget is
    never passed; an early stop (ASHA) frees the rest for new draws. ``num_samples`` is then an upper
    bound. Wraps the Optuna search inside the seeds' repeater, so each decision is a whole
    configuration with all its seeds. Its counts are saved beside the searcher's own (a resume
    goes on with them)."""

    def __init__(self, searcher: Searcher, budget: int, per_configuration: int):
        super().__init__(metric=searcher.metric, mode=searcher.mode)
        self.searcher, self.budget, self.per_configuration = searcher, int(budget), int(per_configuration)
        self.spent, self.live = 0, set()

    def set_search_properties(self, metric, mode, config, **spec) -> bool:
        return self.searcher.set_search_properties(metric, mode, config, **spec)

    def suggest(self, trial_id: str):
        if self.spent + (len(self.live) + 1) * self.per_configuration > self.budget:
            return None if self.live else Searcher.FINISHED  # wait for a running one to free its share
        config = self.searcher.suggest(trial_id)
        if isinstance(config, dict):
            self.live.add(trial_id)
        return config

    def on_trial_result(self, trial_id: str, result: dict) -> None:
        self.searcher.on_trial_result(trial_id, result)

    def on_trial_complete(self, trial_id: str, result=None, error: bool = False, **kwargs) -> None:
        if trial_id in self.live:
            self.live.discard(trial_id)
            self.spent += int((result or {}).get(SPENT, 0) or 0)
        self.searcher.on_trial_complete(trial_id, result=None if error else result, error=error)

    def get_state(self) -> dict:
        """Its counts: Tune's SearchGenerator saves a wrapper's state this way (the base searcher's
        with ``save_to_dir``) and restores it on ``--resume``."""
        return {"spent": self.spent, "live": sorted(self.live)}

    def set_state(self, state: dict) -> None:
        self.spent, self.live = int(state["spent"]), set(state["live"])

    def save(self, checkpoint_path: str) -> None:
        self.searcher.save(checkpoint_path)

    def restore(self, checkpoint_path: str) -> None:
        self.searcher.restore(checkpoint_path)


class SeedRepeater(Repeater):
    """Each configuration Optuna proposes, trained with ``repeat`` seeds (Tune's Repeater: one Tune
    trial, and one MLflow run, per seed; the seed is the repeat's index). Optuna is told once per
    configuration, when all its seeds are done: the objective of the seeds' mean return and mean
    cost, and the constraint mean cost − limit. A failed seed (error, or no finished episode) is
    left out of the means; a configuration whose seeds all failed is told as failed. On resume,
    Tune's SearchGenerator restores the groups (Repeater.get_state) beside Optuna's study."""

    def on_trial_result(self, trial_id, result):
        # Each seed's env steps so far: what its configuration spent (an env-step budget reads it).
        if result and ENV_STEPS in result:
            steps = getattr(self, "_env_steps", None)  # a sweep pickled before this counts from here
            self._env_steps = {**(steps or {}), trial_id: int(result[ENV_STEPS])}

    def on_trial_complete(self, trial_id, result=None, error=False, **kwargs):
        group = self._trial_id_to_group.get(trial_id)
        if group is None:
            return
        if result and ENV_STEPS in result:
            self.on_trial_result(trial_id, result)
        # The trial's score (sweeps/score.py: its final 10% of iterations), its last iteration's
        # values where it has none (a trial of a version before the score).
        keys = ((SCORE_RETURN, SCORE_COST, COST_LIMIT) if result and SCORE_RETURN in result
                else (EPISODE_RETURN, EPISODE_COST, COST_LIMIT))
        ok = not error and result and all(k in result and math.isfinite(result[k]) for k in keys)
        group.report(trial_id, tuple(float(result[k]) for k in keys) if ok else (math.nan,) * 3)
        if not group.finished_reporting():
            return
        steps = getattr(self, "_env_steps", None) or {}
        spent = sum(steps.get(t, 0) for t, g in self._trial_id_to_group.items() if g is group)
        seeds = [s for s in group.scores() if math.isfinite(s[0])]
        if not seeds:
            # Optuna is told a failure without a result (a multi-objective one would read its values).
            told = {SPENT: spent} if isinstance(self.searcher, EnvStepBudget) else None
            self.searcher.on_trial_complete(group.primary_trial_id, result=told, error=True)
            return
        ret, cost, limit = (sum(col) / len(seeds) for col in zip(*seeds))
        # The one objective of a single-objective search, and return and cost of a multi-objective one.
        self.searcher.on_trial_complete(group.primary_trial_id, result={
            METRIC: objective(ret, cost, limit), EPISODE_RETURN: ret, EPISODE_COST: cost, CONSTRAINT: cost - limit,
            "n_seeds": len(seeds), SPENT: spent})


def versions() -> dict:
    import mlflow
    import torch

    from lac_rllib.tasks.versions import runtime_versions

    return {"ray": ray.__version__, "torch": torch.__version__, "mlflow": mlflow.__version__,
            "platform": platform.platform(), **runtime_versions()}


def worker_env(plan: Plan) -> dict | None:
    """The job's runtime env: a user's algorithm's folders on every worker's PYTHONPATH, so the env
    runners and learners a trial starts (``cpus_per_trial`` > 1) unpickle its config classes too
    (a trial adds them to its own path: sweeps/trainable.py). None: nothing to add."""
    folders = [f for f in dict.fromkeys(plan.user_algos.values()) if f]
    if not folders:
        return None
    path = os.pathsep.join([*folders, *filter(None, [os.environ.get("PYTHONPATH")])])
    return {"env_vars": {"PYTHONPATH": path}}


def param_space(plan: Plan, parent_run_id: str) -> dict:
    common = {
        "timesteps": plan.timesteps, "cpus": plan.sweep.cpus_per_trial, "user_tasks": plan.user_tasks,
        "eval_episodes": EVAL_EPISODES if plan.sweep.eval_episodes is None else plan.sweep.eval_episodes,
        "score": plan.sweep.score or SCORES[0],
        "ladder_constraint": plan.sweep.ladder_constraint,  # several constraints: the one a ladder runs along
        "eval_modes": plan.sweep.eval_modes, "eval_every": plan.sweep.eval_every,
        "user_algos": plan.user_algos, spaces.LABELS_KEY: spaces.LABELS,  # how its trials are labelled
        "tracking": {"uri": plan.tracking_uri, "experiment": plan.experiment, "parent_run_id": parent_run_id},
    }
    if plan.pbt is not None:  # PBT: a member per seed, its first fields drawn by Tune, then exploited
        return {**common, "task": plan.tasks[0], "budget": plan.sweep.budget, "sets": plan.sets,
                "seeds": list(plan.seeds), "overrides": spaces.tune_search_space(plan.sweep.search),
                "pbt": {"window": plan.sweep.pbt.window},
                spaces.REPEAT_INDEX: tune.grid_search(list(range(len(plan.seeds))))}
    if plan.trials is None:  # search: Optuna samples the fields; the trial resolves them (spaces.trial_spec)
        return {**common, "task": plan.tasks[0], "budget": plan.sweep.budget, "sets": plan.sets,
                "seeds": list(plan.seeds), "overrides": spaces.tune_search_space(plan.sweep.search)}
    # Each grid trial carries its fields as the plan resolved them (spaces.resolve_trials).
    # Tune turns dataclasses in a config into tuples: each TrialSpec travels as its dict.
    return {**common, "trial": tune.grid_search([dataclasses.asdict(t) for t in plan.trials])}


def at_cluster_concurrency(plan: Plan, cpus: int) -> Plan:
    """The plan at the concurrency a cluster of ``cpus`` CPUs gives (the plan, made before Ray
    connected, counted this machine's), its wall time estimated again from its trials' seconds;
    printed, as the plan's own lines were."""
    concurrency = min(plan.n_trials, max(1, cpus // plan.sweep.cpus_per_trial))
    wall = estimate_wall_s(list(plan.trial_seconds), concurrency) if plan.trial_seconds else plan.estimated_wall_s
    plan = dataclasses.replace(plan, concurrency=concurrency, estimated_wall_s=wall)
    print(f"  cluster: {cpus} CPUs -> {concurrency} trials at once; estimated wall time {duration_text(wall)}, "
          f"{plan.estimated_cpu_h:.1f} CPU-hours", flush=True)
    return plan


def parent_params(plan: Plan, commit: str) -> dict:
    """The parent run's params: the resolved sweep's settings (its file is ``sweep.yaml``) and where it ran."""
    sweep, infra = plan.sweep, plan.infra
    return {"space": plan.space, "task": plan.task or ",".join(plan.tasks), "budget": plan.budget,
            "algo": ",".join(plan.swept_algos or sweep.algo), "seeds": ",".join(map(str, plan.seeds)),
            "set": json.dumps(spaces_plain(plan.sets), default=str), "searcher": sweep.searcher,
            "num_samples": sweep.num_samples, "scheduler": sweep.scheduler, "cpus_per_trial": sweep.cpus_per_trial,
            "max_concurrent": plan.concurrency, "experiment": sweep.experiment, "name": plan.name,
            "address": infra.address, "address_from": infra.address_from, "tracking_uri": infra.tracking_uri,
            "storage": plan.storage, "resume": infra.resume, "max_failures": infra.max_failures,
            "optuna_seed": infra.optuna_seed, "optuna_storage": plan.optuna_storage, "n_trials": plan.n_trials,
            "timesteps": plan.timesteps, "git_commit": commit, **versions()}


def spaces_plain(d: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def run_sweep(plan: Plan, sweep_dir: Path, commit: str) -> int:
    """Run the planned sweep; the plan is all it reads (sweeps/run.py made it from the file and flags)."""
    infra, cpus_per_trial = plan.infra, plan.sweep.cpus_per_trial
    if not ray.is_initialized():  # tests drive sweeps inside their own Ray session
        ray.init(address=infra.address, include_dashboard=False, log_to_driver=False, logging_level="ERROR",
                 runtime_env=worker_env(plan))
    biggest = max((n["Resources"].get("CPU", 0) for n in ray.nodes() if n["Alive"]), default=0)
    if cpus_per_trial > biggest:  # Tune would leave every trial PENDING, silently, forever
        print(f"sweeps/run.py: error: --cpus-per-trial {cpus_per_trial} is more than the largest node of the "
              f"Ray cluster has ({biggest:g} CPUs); accepted: 1..{biggest:g}", file=sys.stderr)
        return 2
    if plan.sweep.max_concurrent is None and infra.address:  # the plan could only count this machine's CPUs
        plan = at_cluster_concurrency(plan, int(ray.cluster_resources().get("CPU", 1)))
    params = parent_params(plan, commit)
    tracker = SweepTracker(plan.tracking_uri, plan.experiment)
    state_file = sweep_dir / SWEEP_FILE
    previous = json.loads(state_file.read_text()) if infra.resume else {}
    parent = tracker.start(
        plan.name, params=params,
        tags={"lac.space": plan.space, "lac.budget": plan.budget, "lac.sweep_name": plan.name,
              "lac.seeds": ",".join(map(str, plan.seeds)), "lac.tasks": ",".join(plan.tasks)},
        run_id=previous.get("parent_run_id"),
    )
    links = tracker.links(parent)
    print_links(links)
    if not infra.resume:
        tracker.set_note(parent, f"**Sweep `{plan.name}` running**: {plan.n_trials} trials of "
                                 f"{plan.timesteps:,} env steps ({plan.space}, "
                                 f"task {plan.task or 'paper tasks'}). "
                                 "The summary replaces this note when the sweep ends.")
    # The record first: from here on a failure leaves a sweep that --resume can pick up (with
    # the same parent run), never a directory that is neither startable nor resumable.
    write_record(sweep_dir, plan, parent)
    try:
        tuner = _tuner(plan, parent, sweep_dir)
        if not infra.resume:
            tracker.client.log_text(parent, json.dumps(plan.record(), indent=2, default=str), "plan.json")
            tracker.client.log_text(parent, plan.sweep.dump(), SWEEP_YAML)  # the file that reruns this sweep
    except BaseException:
        tracker.client.set_tag(parent, STATUS_TAG, "failed to start")
        tracker.client.set_terminated(parent, status="FAILED")
        raise
    # Tune stops gracefully on SIGINT and SIGUSR1 (saving its state); SIGTERM (`kill`, a job
    # scheduler) would kill the driver mid-write. Route it to the same graceful stop.
    previous_term = signal.signal(signal.SIGTERM, lambda *_: os.kill(os.getpid(), signal.SIGUSR1))
    # Tune's newer console output ignores a ProgressReporter; the live table is one (sweeps/live_table.py).
    os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    try:
        grid = tuner.fit()
    finally:
        signal.signal(signal.SIGTERM, previous_term)
    n_errors, n_done = grid.num_errors, grid.num_terminated
    budget, spent = plan.sweep.env_steps_budget, sum(int((r.metrics or {}).get(ENV_STEPS, 0) or 0) for r in grid)
    # An env-step budget ends a search before num_samples once no whole configuration more fits.
    exhausted = budget is not None and spent + len(plan.seeds) * plan.timesteps > budget
    if n_done + n_errors < plan.n_trials and not exhausted:  # stopped by a signal: trials are left to run
        closed = close_open_children(tracker, parent, "KILLED")
        tracker.client.set_tag(parent, STATUS_TAG, "interrupted")
        tracker.client.set_terminated(parent, status="KILLED")
        print(f"interrupted: {n_done} of {plan.n_trials} trials finished ({n_errors} failed, {closed} runs closed "
              f"as KILLED); resume with --resume", file=sys.stderr, flush=True)
        return 130
    stopped = close_open_children(tracker, parent, "FINISHED", tags={STOPPED_TAG: "1"})  # ASHA's early stops
    if plan.pbt is not None:  # the population's schedules, returns and costs on one figure (sweeps/pbt.py)
        _log_lineage(tracker, parent, plan)
    seeds = plan.seeds
    seed_text = (f"seeds {seeds[0]}..{seeds[-1]}" if seeds == tuple(range(seeds[0], seeds[-1] + 1))
                 else f"seeds {', '.join(map(str, seeds))}")
    outcome = (f"{n_done} of {plan.n_trials} trials finished ({stopped} stopped early by the scheduler), "
               f"{n_errors} failed; {seed_text}"
               + (f"; {spent:,} of its {budget:,} env steps spent (env_steps_budget)" if budget is not None else ""))
    close_sweep(tracker, parent, n_errors, heading=f"**Sweep `{plan.name}`**: {outcome}.", plan=plan)
    print(f"sweep done: {outcome}; MLflow parent run {parent}")
    print_links(links, plan.tracking_uri)
    return 0


def _log_lineage(tracker: SweepTracker, parent: str, plan: Plan) -> None:
    """``pbt_population.png`` on the parent run; a failure is said, not raised (the sweep trained)."""
    import tempfile

    from sweeps.pbt import lineage_figure

    try:
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "pbt_population.png")
            if lineage_figure(tracker.client, parent, path, tuple(plan.sweep.search)):
                tracker.client.log_artifact(parent, path)
    except Exception as e:  # noqa: BLE001
        print(f"pbt: the population's figure failed: {type(e).__name__}: {e}", file=sys.stderr, flush=True)


def print_links(links: dict, uri: str | None = None) -> None:
    """Where to look in the MLflow UI (the runs in "Model training" mode, and the parent run)."""
    if uri and not uri.startswith(("http://", "https://")):
        print(f"  start the UI: mlflow ui --backend-store-uri {uri}")
    print(f"  MLflow runs:       {links['runs']}")
    print(f"  MLflow parent run: {links['run']}", flush=True)


def _tuner(plan: Plan, parent: str, sweep_dir: Path) -> tune.Tuner:
    """Tune's state if the sweep has one (resume), else a new Tuner (also for a sweep whose
    first start failed before Tune wrote anything)."""
    # A multi-CPU trial reserves a bundle per env runner, where RLlib places them (config.run_resources).
    sweep, infra = plan.sweep, plan.infra
    trainable = tune.with_resources(SweepTrial, run_resources(sweep.cpus_per_trial))
    if infra.resume and tune.Tuner.can_restore(str(sweep_dir)):
        return tune.Tuner.restore(str(sweep_dir), trainable=trainable, resume_unfinished=True, resume_errored=False)
    space = param_space(plan, parent)
    failure = tune.FailureConfig(max_failures=infra.max_failures)
    ckpt = tune.CheckpointConfig(checkpoint_frequency=1, num_to_keep=2, checkpoint_at_end=True)
    run_config = tune.RunConfig(
        name=plan.name, storage_path=plan.storage, failure_config=failure, checkpoint_config=ckpt,
        progress_reporter=LiveTable(plan.n_trials, plan.concurrency), verbose=1,
    )
    if plan.pbt is not None:
        return _pbt_tuner(plan, trainable, space, failure, run_config)
    search = search_algorithm(plan)
    scheduler, live = None, plan.concurrency
    if plan.early_stopping:  # a configuration's seeds decided together (sweeps/scheduler.py)
        scheduler = ConfigurationASHA(time_attr=ENV_STEPS, metric=METRIC, mode=MODE, max_t=plan.timesteps,
                                      grace_period=plan.early_stopping[0], seeds=len(plan.seeds))
        # A seed paused at a rung stays live (Tune's limit counts it) until its siblings arrive:
        # room for a whole configuration, or they would wait for each other forever. CPUs still
        # bound how many run.
        live = max(plan.concurrency, len(plan.seeds))
    return tune.Tuner(
        trainable, param_space=space,
        tune_config=tune.TuneConfig(num_samples=plan.n_trials if search else 1, search_alg=search,
                                    scheduler=scheduler, max_concurrent_trials=live,
                                    trial_name_creator=_trial_name),
        run_config=run_config,
    )


def _pbt_tuner(plan: Plan, trainable, space: dict, failure, run_config) -> tune.Tuner:
    """``searcher: pbt``: the population as one grid over its members (Tune's random draw of each
    member's first fields, seeded), under :class:`sweeps.pbt.ConstrainedPBT`. Members checkpoint
    where they pause, at each exploit time (synchronous PBT pauses every member there), and every
    checkpoint is kept: a donor that trains on before its copy starts must not delete what it copies
    (Tune warns of this with ``num_to_keep`` <= 2)."""
    from ray.tune.search import BasicVariantGenerator

    from sweeps.objective import OBJECTIVE_WINDOW
    from sweeps.pbt import ConstrainedPBT

    search, pbt = plan.sweep.search, plan.sweep.pbt
    scheduler = ConstrainedPBT(time_attr=ENV_STEPS, metric=OBJECTIVE_WINDOW, mode=MODE, intervals=plan.pbt,
                               mutations=pbt_mutations(search), bounds=pbt_bounds(search),
                               quantile_fraction=pbt.quantile, resample_probability=pbt.resample_probability,
                               growth=pbt.growth, migrate=pbt.migrate, seed=plan.infra.optuna_seed)
    run_config = dataclasses.replace(run_config, checkpoint_config=tune.CheckpointConfig(
        checkpoint_frequency=0, num_to_keep=None, checkpoint_at_end=True))
    return tune.Tuner(
        trainable, param_space=space,
        tune_config=tune.TuneConfig(num_samples=1, scheduler=scheduler, max_concurrent_trials=plan.concurrency,
                                    search_alg=BasicVariantGenerator(random_state=plan.infra.optuna_seed),
                                    trial_name_creator=_trial_name, reuse_actors=False),
        run_config=run_config,
    )


def pbt_mutations(search: dict) -> dict:
    """Tune's ``hyperparam_mutations`` of a search: a choice's values (shifted along or resampled),
    every other range as its Tune domain (scaled ×0.8/×1.2, or resampled)."""
    return {name: list(d.args) if d.kind == "choice" else spaces.tune_search_space({name: d})[name]
            for name, d in search.items()}


def pbt_bounds(search: dict) -> dict:
    """Each searched field's (kind, low, high), or ("choice", values): what PBT's explore is clipped to."""
    return {name: (d.kind, *d.args) if d.kind != "choice" else ("choice", tuple(d.args)) for name, d in search.items()}


def search_algorithm(plan: Plan) -> SeedRepeater | None:
    """A search's Tune searcher (Optuna behind a SeedRepeater); None for a grid of configurations."""
    if plan.trials is not None:
        return None
    sweep, infra = plan.sweep, plan.infra
    # The study lives in its own storage (plan.optuna_storage) under the sweep's name:
    # optuna-dashboard opens it, and a resumed sweep goes on with the same study. TPE reads
    # the constraint each configuration is told (ConstrainedOptunaSearch); random ignores it.
    # A multi-objective search (motpe, nsga2) has two: return up, cost down; its result is the
    # study's Pareto set (sweeps/reports/report.py, pareto.json), the constraint marking the feasible part.
    # The sampler's random start is the sweep's, not Optuna's default (sweeps/search.py).
    sampler = make_sampler(sweep.searcher, sweep.num_samples, infra.optuna_seed)
    metric, mode = ((list(MULTI_OBJECTIVES), ["max", "min"]) if sweep.multi_objective else (METRIC, MODE))
    optuna_search = ConstrainedOptunaSearch(sampler=sampler,
                                            metric=metric, mode=mode, study_name=plan.name,
                                            storage=optuna.storages.RDBStorage(plan.optuna_storage))
    inner = optuna_search
    if sweep.env_steps_budget is not None:  # drawn while the spent env steps allow a whole configuration more
        inner = EnvStepBudget(optuna_search, sweep.env_steps_budget, len(plan.seeds) * plan.timesteps)
    return SeedRepeater(inner, repeat=len(plan.seeds))


def _trial_name(trial) -> str:
    return spaces.trial_spec(trial.config).label()


def close_open_children(tracker: SweepTracker, parent: str, status: str, tags: dict | None = None) -> int:
    """Close the child runs a trial left RUNNING (its process was stopped before it could)."""
    n = 0
    for run in tracker.children(parent):
        if run.info.status == "RUNNING":
            for k, v in (tags or {}).items():
                tracker.client.set_tag(run.info.run_id, k, v)
            tracker.client.set_terminated(run.info.run_id, status=status)
            n += 1
    return n
