"""The sweep service: ``python sweeps/run.py --space ablation`` (Ray Tune + Optuna, tracked in MLflow).

Every argument is checked, and the plan printed, before Ray starts. One MLflow parent run per
sweep, one child run per trial; the Tune experiment lives in ``--storage``/``--name`` so that
``--resume`` (same arguments) continues a sweep whose driver was killed.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

from pydantic import ValidationError

from lac_rllib.algorithms.registry import (
    ALGO_FIELD,
    DEFAULT_ALGO,
    algos_text,
    check_algo,
    is_builtin,
    module_dir,
    plan_update_s,
)
from sweeps import spaces, sweep_file
from sweeps.calibration import machine_factor
from sweeps.lock import DriverLock, SweepLocked
from sweeps.plan import Infra, Plan
from sweeps.record import SWEEP_FILE, resume_differences
from sweeps.sweep_file import SweepFile
from sweeps.tracking import check_reachable, default_tracking_uri

# The plan's estimate, per preset: env steps per second of one trial on 1 CPU, sampling and the
# update's part every algorithm has (calibration: docs/sweeps.md); each algorithm adds its own
# update's seconds per env step (``plan_update_s`` in its folder, read through the registry).
RATE = {"tiny": 405.0, "safety_gym": 377.0, "mujoco": 185.0}
STARTUP_S = 15.0
#: The envs per runner each preset's RATE holds at (the presets' own: the tiny task's quick trials
#: and the Safety-Gymnasium presets sample 10 envs per runner, the MuJoCo presets 5).
RATE_ENVS = {"tiny": 10, "safety_gym": 10, "mujoco": 5}
#: The env's share of a sampled step's time at one env per runner; the rest (the policy's forward,
#: RLlib's per-step work) a vector env of N envs divides by N. From PointGoal1's sampling, 202 steps/s
#: at one env and 450 at ten (docs/speed.md, "Sampling"): s + (1 - s)/10 = 202/450. A task's
#: ``step_cost`` scales this share.
ENV_SHARE = 0.39
#: The same share in an evaluation block (one env, the policy's forward a step, none of RLlib's
#: sampling machinery): PointButton1's blocks took 2.7x PointGoal1's at a step cost of 3.3 in the
#: table2 quick sweep (docs/sweeps.md, "What the plan's estimate is").
EVAL_ENV_SHARE = 0.75
#: The command's name in its help and errors: the console script, or the file as ``python`` ran it.
PROG = "lac-sweep" if Path(sys.argv[0]).name == "lac-sweep" else "sweeps/run.py"
#: The most trials a sweep may plan unless --max-trials says more: counted before any is built
#: (the plan holds each trial's resolved fields; ~10 ms and a few KB each).
MAX_TRIALS = 5_000
#: The flag each resolved key of a sweep comes from when it is given (sweep_file.Origin).
FLAG_OF = {"task": "--task", "budget": "--budget", "num_samples": "--num-samples", "scheduler": "--scheduler",
           "max_concurrent": "--max-concurrent", "cpus_per_trial": "--cpus-per-trial",
           "experiment": "--experiment", "name": "--name"}


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low:
            raise argparse.ArgumentTypeError(f"{text} is invalid; accepted: an integer >= {low}")
        return value
    return parse


def _name(text: str) -> str:
    try:
        return sweep_file.check_name(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _budget(text: str) -> str | int:
    if text.isdigit() and int(text) > 0:
        return int(text)
    if text in spaces.BUDGETS:
        return text
    raise argparse.ArgumentTypeError(f"{text!r} is invalid; accepted: {' | '.join(spaces.BUDGETS)} or env steps "
                                     "(an integer > 0)")


def parse_args(argv=None) -> argparse.Namespace:
    """The command line. A flag left out is None: the sweep file (or its default) decides."""
    p = argparse.ArgumentParser(prog=PROG, description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--space", choices=sweep_file.builtin_spaces(),
                      help="a built-in sweep (its file is in sweeps/builtin/)")
    what.add_argument("--config", metavar="FILE.yaml", help="a sweep file (reference: docs/sweeps.md)")
    p.add_argument("--task", default=None,
                   help=f"task id (docs/tasks.md; default: the file's, else {spaces.DEFAULT_TASK})")
    p.add_argument("--budget", type=_budget, default=None,
                   help="; ".join(f"{k}: {b.describe()}" for k, b in spaces.BUDGETS.items()) + "; or env steps N")
    p.add_argument("--seeds", type=_int_at_least(1), default=None,
                   help="seeds per configuration (search: per sampled configuration; default 3)")
    p.add_argument("--seed-start", type=_int_at_least(0), default=None,
                   help="the first seed (default 0): confirmation runs use seeds no search saw")
    p.add_argument("--num-samples", type=_int_at_least(1), default=None,
                   help="configurations a search samples (default 20)")
    p.add_argument("--max-concurrent", type=_int_at_least(1), default=None,
                   help="trials at once (default: CPUs / cpus-per-trial)")
    p.add_argument("--cpus-per-trial", type=_int_at_least(1), default=None,
                   help="CPUs per trial: as many env runners sample and as many torch threads update (default 1)")
    p.add_argument("--scheduler", choices=("none", "asha"), default=None)
    p.add_argument("--address", default=None,
                   help="Ray cluster address (host:port or auto; default: $RAY_ADDRESS, else local Ray)")
    p.add_argument("--tracking-uri", default=None,
                   help="MLflow tracking URI (default: sqlite store in the working dir)")
    p.add_argument("--experiment", default=None, help="MLflow experiment name (default lac-sweeps)")
    p.add_argument("--storage", default="ray_results",
                   help="Tune storage path (on a cluster: an absolute path every node mounts)")
    p.add_argument("--name", type=_name, default=None,
                   help="sweep name (default: FILE-TASK-BUDGET); --resume finds it by name")
    p.add_argument("--resume", action="store_true", help="continue the sweep of the same name")
    p.add_argument("--max-failures", type=_int_at_least(0), default=2, help="retries of a failed trial (node loss)")
    p.add_argument("--max-trials", type=_int_at_least(1), default=MAX_TRIALS,
                   help=f"refuse a sweep that plans more trials (default {MAX_TRIALS:,}; raise it on a cluster)")
    p.add_argument("--optuna-seed", type=int, default=0, help="seed of the search's sampler")
    p.add_argument("--optuna-storage", default=None,
                   help="Optuna storage URL of a search's study (default: optuna.db beside a local MLflow "
                        "store, else in --storage); open it with optuna-dashboard URL")
    p.add_argument("--confirm-top", type=_int_at_least(1), default=None, metavar="K",
                   help="after the sweep, rerun its K best feasible configurations (by the lower end of the "
                        "return interval) beside the default on fresh seeds (sweeps/confirm.py)")
    p.add_argument("--confirm-seeds", type=_int_at_least(1), default=None, metavar="N",
                   help="seeds of the confirmation (default: the sweep's count, at least 3)")
    p.add_argument("--confirm-budget", type=_budget, default=None, metavar="BUDGET",
                   help="the confirmation's budget: the sweep's (default) or a larger one")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="set a field in every trial (the swept value wins); e.g. nu_max_adaptive=False; "
                        f"algo={algos_text('|')} picks the algorithm (fields: docs/config.md), or "
                        "algo=mypkg.safe_algo your own algorithm's module (docs/baselines.md)")
    return p.parse_args(argv)


def check_address(address: str | None, source: str | None = "--address") -> None:
    """``source`` says where the address came from: ``--address``, or ``RAY_ADDRESS`` (what
    ``ray job submit`` sets for the driver it starts)."""
    if address in (None, "auto", "local"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"{source} {address!r}: accepted: auto, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as e:
        raise ValueError(f"{source} {address}: cannot connect ({e}); is `ray start --head` running there?") from None


def check_storage(storage: str) -> None:
    # The sweep's record, lock and Tune state are written through the local filesystem: a URI
    # such as s3://bucket/x used to become a local directory named "s3:" (pathlib folds "//").
    if "://" in storage and not storage.startswith("file://"):
        raise ValueError(f"--storage {storage}: object stores are not supported yet; accepted: a filesystem path "
                         "(on a cluster, one every node mounts at the same place, e.g. NFS)")
    path = Path(storage.removeprefix("file://")).resolve()
    missing = [p for p in (path, *path.parents) if not p.exists()]
    try:  # create it to know it can be (root passes os.access checks on /proc), then leave no trace
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".lac-write-probe-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as e:
        raise ValueError(f"--storage {storage} is not a writable directory ({e.strerror}); "
                         "accepted: a directory this user can create and write") from None
    finally:
        for p in missing:  # deepest first
            try:
                p.rmdir()
            except OSError:
                pass


def check_shared(uri: str, storage: str, source: str | None = "--address") -> None:
    """On a cluster every trial runs on some node: the tracking store and the storage path must
    be the same place for all of them, not one local copy per node."""
    if uri.startswith(("sqlite:", "file:")) or "://" not in uri:
        raise ValueError(f"--tracking-uri {uri} with {source}: each node would write its own local store; "
                         "accepted: http(s)://HOST:PORT of an mlflow server every node reaches (docker/README.md)")
    if not storage.startswith("file://") and not os.path.isabs(storage):
        raise ValueError(f"--storage {storage} with {source}: a relative path is a different directory on every "
                         "node; accepted: an absolute path every node mounts at the same place")


def make_plan(args) -> Plan:
    """The one pass from the command line to the trials: file and flags → the resolved sweep
    (:func:`resolve_sweep`) → its trials with their full configs (``spaces.trial_params``) → the
    estimate and where it goes (:func:`plan_sweep`). Every input is checked here, before Ray starts."""
    sweep, space, origin = resolve_sweep(args)
    address = args.address or os.environ.get("RAY_ADDRESS") or None
    infra = Infra(address=address, address_from="--address" if args.address else "RAY_ADDRESS" if address else None,
                  tracking_uri=args.tracking_uri or default_tracking_uri(), storage=args.storage,
                  resume=args.resume, max_failures=args.max_failures, optuna_seed=args.optuna_seed,
                  optuna_storage=args.optuna_storage)
    check_address(address, infra.address_from)
    check_storage(args.storage)
    if address not in (None, "local"):
        check_shared(infra.tracking_uri, args.storage, infra.address_from)
    check_reachable(infra.tracking_uri)
    plan = plan_sweep(sweep, space, infra, module_search_dirs(args), origin, max_trials=args.max_trials)
    if args.confirm_top:
        plan = dataclasses.replace(plan, confirm=check_confirm(plan, args))
    return plan


def module_search_dirs(args) -> tuple[str, ...]:
    """Where a user's module (an env factory's, an algorithm's) is looked up after the Python path:
    beside the sweep file, then here."""
    return tuple(dict.fromkeys(((str(Path(args.config).resolve().parent),) if args.config else ())
                               + (os.getcwd(),)))


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
    tasks, user_tasks = resolve_tasks(sweep, search_dirs, origin)
    seeds = sweep.seed_list()
    count = sweep.num_samples * len(seeds) if sweep.is_search else spaces.count_trials(sweep, tasks)
    if count > max_trials:
        what = "num_samples × seeds" if sweep.is_search else "tasks × configurations × algorithms × seeds"
        raise ValueError(f"{origin(('num_samples',) if sweep.is_search else ())}: the sweep plans {count:,} trials "
                         f"({what}), more than --max-trials {max_trials:,}; accepted: a smaller sweep, or "
                         "--max-trials N where a cluster can run them")
    sets = trial_sets(sweep)
    trials = None
    if not sweep.is_search:
        trials = spaces.resolve_trials(spaces.expand(sweep, tasks), sweep.budget, sets)
    from lac_rllib.constrained.cpus import check_cpus

    # A search is estimated at the fields it runs before Optuna's samples (the sampled T is not known yet).
    first = trials or [dataclasses.replace(spaces.trial_spec(
        {"task": tasks[0], "budget": sweep.budget, "sets": sets, "overrides": {}}), seed=0)]
    for t in first:
        check_cpus(t.params.get("num_envs_per_env_runner", 1), cpus, origin(("cpus_per_trial",)))
    # search: each sampled configuration is trained with every seed (sweeps/sweep.py, SeedRepeater)
    n_trials = len(trials) if trials is not None else sweep.num_samples * len(seeds)
    concurrency = min(sweep.max_concurrent or max(1, (os.cpu_count() or 1) // cpus), n_trials)
    calibration = machine_factor(infra.tracking_uri, sweep.experiment, nominal_trial_s)
    evals = [estimate_eval_s(t.task, t.timesteps, t.params, sweep) for t in trials or first * n_trials]
    per_trial = [calibration(t.algo) * (estimate_trial_s(t.task, t.timesteps, t.params, cpus) + e)
                 for t, e in zip(trials or first * n_trials, evals)]
    eval_share = eval_share_of(evals, per_trial, trials or first * n_trials, calibration)
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
    name = sweep.name
    optuna_storage = None
    if sweep.is_search:
        optuna_storage = infra.optuna_storage or default_optuna_storage(infra.tracking_uri, infra.storage)
        check_optuna_study(optuna_storage, name, infra.resume)
    return Plan(
        sweep=sweep, infra=infra, space=space, tasks=tuple(tasks), user_tasks=user_tasks, trials=trials,
        n_trials=n_trials, concurrency=concurrency, sets=sets, timesteps=timesteps, early_stopping=early,
        estimated_wall_s=estimate_wall_s(per_trial, concurrency), estimated_cpu_h=sum(per_trial) * cpus / 3600,
        trial_seconds=tuple(per_trial), eval_share=eval_share,
        calibration=(calibration.factor, calibration.source),
        name=name, storage=str(Path(infra.storage.removeprefix("file://")).resolve()), optuna_storage=optuna_storage,
        user_algos=user_algos(sweep),
    )


def check_confirm(plan: Plan, args) -> tuple[int, int, str | int]:
    """``--confirm-top K [--confirm-seeds N] [--confirm-budget B]`` checked before Ray starts: one
    task, a budget at least the sweep's (a smaller one would confirm something else)."""
    if len(plan.tasks) != 1:
        raise ValueError(f"--confirm-top with {len(plan.tasks)} tasks: a confirmation reruns one task's winners; "
                         "accepted: a sweep of one task")
    budget = args.confirm_budget if args.confirm_budget is not None else plan.sweep.budget
    steps = spaces.get_budget(budget).for_task(plan.tasks[0])[0]
    if steps < plan.timesteps:
        raise ValueError(f"--confirm-budget {budget}: {steps:,} env steps is less than the sweep's {plan.timesteps:,}; "
                         "accepted: the same or a larger budget")
    return args.confirm_top, args.confirm_seeds or max(len(plan.seeds), 3), budget


def resolve_sweep(args) -> tuple[SweepFile, str, sweep_file.Origin]:
    """The sweep file (``--config``, or the built-in ``--space``) with the flags and the defaults
    applied, checked again as a whole: the sweep every later step reads, and ``sweep.yaml``.
    Returns it, the sweep's kind (the built-in space or the file's stem) and where each key came from."""
    path = Path(args.config) if args.config else sweep_file.builtin_path(args.space)
    base, origin = sweep_file.load_with_origin(path)
    dirs = module_search_dirs(args)
    space = args.space or path.stem
    data = base.model_dump(exclude_none=True)
    if args.task:
        data["task"] = [args.task]
    if args.budget is not None:
        data["budget"] = args.budget
    if args.seeds is not None or args.seed_start is not None:
        old = base.seed_list()
        data["seeds"] = {"count": args.seeds or len(old),
                         "start": args.seed_start if args.seed_start is not None else old[0]}
    algo_pairs = [p for p in args.set if p.partition("=")[0].strip() == ALGO_FIELD]
    cli_sets = parse_set_pairs([p for p in args.set if p not in algo_pairs])
    if algo_pairs:
        try:
            algo = check_algo(algo_pairs[-1].partition("=")[2].strip(), dirs)
        except ValueError as e:
            raise ValueError(f"--set {ALGO_FIELD}: {e}") from None
        if sweeps_algo(base):
            raise ValueError(f"--set {algo_pairs[-1]}: {path.name} sweeps algo itself ({list(swept_algos(base))}); "
                             "accepted: --set of fields every algorithm it runs has")
        data["algo"] = [algo]
    data["set"] = {**data.get("set", {}), **cli_sets}
    for key in ("num_samples", "scheduler", "max_concurrent", "cpus_per_trial", "experiment"):
        if getattr(args, key) is not None:
            data[key] = getattr(args, key)
    flags = {(k,): f for k, f in FLAG_OF.items() if getattr(args, k) is not None}
    flags |= {("set", k): f"--set {k}" for k in cli_sets}
    if algo_pairs:
        flags[("algo",)] = f"--set {ALGO_FIELD}"
    if args.seeds is not None:
        flags[("seeds", "count")] = "--seeds"
    if args.seed_start is not None:
        flags[("seeds", "start")] = "--seed-start"
    origin = origin.with_flags(flags)
    data.setdefault("task", [spaces.DEFAULT_TASK])
    data.setdefault("budget", "quick")
    data.setdefault("seeds", {"count": 3, "start": 0})
    data.setdefault("searcher", "tpe" if base.is_search else "grid")
    data.setdefault("scheduler", "none")
    data.setdefault("score", "train" if data.get("eval_episodes") == 0 else "eval")
    data.setdefault("cpus_per_trial", 1)
    data.setdefault("experiment", "lac-sweeps")
    if base.is_search:
        data.setdefault("num_samples", 20)
    elif "groups" not in data:  # the file's one group (or one configuration), named after the file
        group = sweep_file.safe_name(space)
        data["groups"] = {group: {"grid": data.pop("grid", {})}} if data.get("grid") else {group: {}}
    try:
        sweep = SweepFile.model_validate(data, context={"search_dirs": dirs})
        sweep_file.check_fields(sweep, dirs)
    except sweep_file.FieldError as e:
        raise ValueError(f"{origin(e.loc)}: {e.message}") from None
    except ValidationError as e:  # a flag's value the file's schema refuses
        raise ValueError(sweep_file.first_error(e, origin)) from None
    if args.name or not sweep.name:
        tasks = sweep.task
        what = ((tasks[0] if isinstance(tasks[0], str) else tasks[0].task_id()).split("/")[-1]
                if len(tasks) == 1 else f"{len(tasks)}-tasks")
        # Derived from the file's stem and the task: made safe rather than refused (it becomes a path).
        sweep = sweep.model_copy(update={"name": args.name or sweep_file.safe_name(f"{space}-{what}-{sweep.budget}")})
    return sweep, space, origin


def parse_set_pairs(pairs: list[str]) -> dict:
    """``--set FIELD=VALUE`` pairs as values (Python literals, else the text); their names and
    values are checked with the sweep's fields (``sweep_file.check_fields``)."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--set {pair!r}: expected FIELD=VALUE")
        try:
            out[name.strip()] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[name.strip()] = raw  # plain strings such as informative / next
    return out


def swept_algos(sweep: SweepFile) -> tuple:
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    found = [v for g in groups for v in g.grid.get(ALGO_FIELD, ())]
    if sweep.search and ALGO_FIELD in sweep.search:
        found += list(sweep.search[ALGO_FIELD].values_to_check())
    if sweep.grid and ALGO_FIELD in sweep.grid:
        found += list(sweep.grid[ALGO_FIELD])
    return tuple(dict.fromkeys(found))


def user_algos(sweep: SweepFile) -> dict[str, str]:
    """Each user's algorithm the sweep names (checked when the file was read) → the folder its
    trials import it from (Ray's workers do not share this process's path)."""
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    named = [*sweep.algo, *swept_algos(sweep), *(s[ALGO_FIELD] for s in (sweep.set, *(g.set for g in groups))
                                                 if ALGO_FIELD in s)]
    return {a: module_dir(a) for a in dict.fromkeys(named) if not is_builtin(a)}


def sweeps_algo(sweep: SweepFile) -> bool:
    return bool(swept_algos(sweep)) or len(sweep.algo) > 1


def trial_sets(sweep: SweepFile) -> dict:
    """What every trial sets: the sweep's ``set``, and its algorithm when it runs one baseline."""
    sets = {k: sweep_file.to_field_value(v) for k, v in sweep.set.items()}
    if len(sweep.algo) == 1 and sweep.algo[0] != DEFAULT_ALGO:
        sets[ALGO_FIELD] = sweep.algo[0]
    return sets


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
                             preset=task.preset, kwargs=task.kwargs, search_dirs=search_dirs)
        except ValueError as e:
            raise ValueError(f"{origin(('task', i))}: {e}") from None
        ids.append(spec.id)
        user[spec.id] = definition(spec)
    return ids, user


def default_optuna_storage(tracking_uri: str, storage: str) -> str:
    """``optuna.db`` beside a local MLflow store (sqlite), else in the Tune storage directory.

    Only the driver writes it (Tune's searcher runs there), so a file is enough on a cluster too.
    """
    if tracking_uri.startswith("sqlite:///"):
        folder = Path(tracking_uri[len("sqlite:///"):]).parent
    else:
        folder = Path(storage.removeprefix("file://")).resolve()
    return f"sqlite:///{folder / 'optuna.db'}"


def check_optuna_study(url: str, name: str, resume: bool) -> None:
    """A fresh search must not adopt a study left by another sweep of the same name."""
    if not url.startswith(("sqlite:///", "postgresql", "mysql")):
        raise ValueError(f"--optuna-storage {url!r}: accepted: an SQLAlchemy URL (sqlite:///PATH.db, postgresql://…, "
                         "mysql://…)")
    if resume or (url.startswith("sqlite:///") and not Path(url[len("sqlite:///"):]).exists()):
        return
    import optuna

    try:
        studies = {s.study_name for s in optuna.get_all_study_summaries(url)}
    except Exception as e:  # any failure means the storage is unusable
        raise ValueError(f"--optuna-storage {url}: cannot be opened ({e})") from None
    if name in studies:
        raise ValueError(f"an Optuna study named {name!r} exists in {url}; pass --resume, another --name, or "
                         f"delete it (optuna delete-study --storage {url} --study-name {name})")


def seconds_per_env_step(task: str, envs: int | None = None) -> float:
    """Rough seconds of one sampled env step of ``task`` at ``envs`` envs per runner (None: the
    rate's own): its preset's rate, the env's share scaled by the task's ``step_cost`` (a Button1
    step costs ~3 Goal1 steps), the rest divided over the vector env's envs."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    ref = RATE_ENVS.get(spec.preset, 1)
    n = envs or ref
    at = (ENV_SHARE * spec.step_cost + (1 - ENV_SHARE) / n) / (ENV_SHARE + (1 - ENV_SHARE) / ref)
    return at / _rate(spec.preset)


def eval_seconds_per_env_step(task: str) -> float:
    """Rough seconds of one evaluation step of ``task``: its preset's rate, the env's share
    (``EVAL_ENV_SHARE``) scaled by the task's ``step_cost``."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    return (1 + EVAL_ENV_SHARE * (spec.step_cost - 1)) / _rate(spec.preset)


def _rate(preset: str) -> float:
    """``RATE`` of ``preset``; an unknown preset (a user env's) gets the slowest."""
    return RATE.get(preset, min(RATE.values()))


def estimate_trial_s(task: str, steps: int, params: dict, cpus: int) -> float:
    """Rough wall seconds of one trial of ``steps`` env steps whose fields are ``params``
    (``spaces.trial_params``): start-up, then env steps at the task's rate
    (:func:`seconds_per_env_step`), plus the algorithm's own update share (LAC's chain grows with
    T; measured on this project's 2-core machine)."""
    from lac_rllib.tasks import get_task

    extra = plan_update_s(params.get(ALGO_FIELD, DEFAULT_ALGO), params, get_task(task).preset) * steps
    envs = params.get("num_envs_per_env_runner")
    return STARTUP_S + (steps * seconds_per_env_step(task, envs) + extra) / cpus ** 0.5


def estimate_eval_s(task: str, steps: int, params: dict, sweep: SweepFile) -> float:
    """Rough seconds of a trial's evaluation blocks (sweeps/trainable.py): ``eval_episodes``
    episodes per mode its algorithm has, at the end and every ``eval_every`` iterations, at the
    task's evaluation rate (:func:`eval_seconds_per_env_step`: one env, a policy forward a step)."""
    from lac_rllib.algorithms.registry import actions
    from lac_rllib.tasks import get_task

    episodes = 10 if sweep.eval_episodes is None else sweep.eval_episodes
    if not episodes:
        return 0.0
    algo = params.get(ALGO_FIELD, DEFAULT_ALGO)
    modes = [m for m in sweep.eval_modes or ("generator", "stochastic") if m == "stochastic" or m in actions(algo)]
    per_iteration = params.get("env_steps_per_iteration") or params.get("train_batch_size_per_learner") or 0
    blocks = 1 + (int(steps // per_iteration) // sweep.eval_every if sweep.eval_every and per_iteration else 0)
    # Each episode counted at the task's episode limit (TaskSpec.episode_steps; episodes may end sooner).
    return blocks * len(modes) * episodes * get_task(task).episode_steps * eval_seconds_per_env_step(task)


def eval_share_of(evals: list[float], per_trial: list[float], trials, calibration) -> float:
    """The evaluation blocks' share of the trials' estimated time."""
    spent = sum(calibration(t.algo) * e for t, e in zip(trials, evals))
    total = sum(per_trial)
    return spent / total if total else 0.0


def nominal_trial_s(params: dict) -> float | None:
    """What the rates say an earlier trial (its MLflow params, as logged) took, to set against its
    run's span (sweeps/calibration.py); None: not comparable."""
    from sweeps.results import param_value
    from sweeps.tracking import P_TASK, P_TIMESTEPS

    try:
        fields = {k: param_value(v) for k, v in params.items()}
        cpus = int(fields.get("torch_threads", 1))  # a trial's threads are its CPUs (sweeps/trainable.py)
        return estimate_trial_s(str(fields[P_TASK]), int(fields[P_TIMESTEPS]), fields, cpus)
    except Exception:  # a run of another version, a task not registered here: leave it out
        return None


def estimate_wall_s(per_trial: list[float], concurrency: int) -> float:
    """Trials taken longest first onto ``concurrency`` slots (Tune starts them in grid order, so
    this is a floor when the longest come last)."""
    slots = [0.0] * concurrency
    for t in sorted(per_trial, reverse=True):
        slots[slots.index(min(slots))] += t
    return max(slots)


def print_plan(plan: Plan) -> None:
    sweep, infra = plan.sweep, plan.infra
    tasks = ", ".join(plan.tasks) if len(plan.tasks) <= 3 else f"{len(plan.tasks)} tasks ({plan.tasks[0]}, ...)"
    print(f"sweep '{plan.name}': {plan.space} ({', '.join(plan.swept_algos or sweep.algo)})  "
          f"task {tasks}  budget {sweep.budget}")
    if sweep.description:
        print(f"  {sweep.description}")
    seeds = plan.seeds
    contiguous = seeds == tuple(range(seeds[0], seeds[-1] + 1))
    seed_text = f"seeds {seeds[0]}..{seeds[-1]}" if contiguous else f"seeds {list(seeds)}"
    what = f"{sweep.num_samples} Optuna {sweep.searcher.upper()} samples x " if sweep.is_search else ""
    print(f"  trials: {plan.n_trials}  ({what}{len(seeds)} seed(s) per configuration: {seed_text})")
    episodes = sweep.eval_episodes if sweep.eval_episodes is not None else 10
    modes = sweep.eval_modes or ["generator", "stochastic"]
    print(f"  score: {sweep.score} ("
          + (f"the trained policy's deterministic action over {episodes} held-out evaluation episodes"
             if sweep.score == "eval" else "the mean over each trial's final 10% of training iterations")
          + (f"; evaluation block: {episodes} episodes x {', '.join(modes)} at each trial's end"
             + (f" and every {sweep.eval_every} iterations" if sweep.eval_every else "")
             + f", ~{plan.eval_share:.0%} of the estimated time" if episodes else "; no evaluation block")
          + ")")
    print(f"  env steps per trial: {plan.timesteps:,}   "
          f"concurrency: {plan.concurrency} x {sweep.cpus_per_trial} CPU"
          f"{'' if not infra.address else f' (cluster {infra.address} from {infra.address_from}: capped by its CPUs)'}")
    print(f"  estimated wall time: ~{plan.estimated_wall_s / 60:.0f} min at {plan.concurrency} trials at a time, "
          f"{plan.estimated_cpu_h:.1f} CPU-hours (rough; calibrated: {plan.calibration[1]})")
    if plan.estimated_wall_s > 4 * 3600 and not infra.address:
        print("  too long for one machine? the same command runs on a Ray cluster: --address HEAD:PORT "
              "(set-up: docker/README.md)")
    if plan.early_stopping:
        grace, why, rungs = plan.early_stopping
        print(f"  early stopping: ASHA per configuration (its seeds' mean objective at equal env steps; "
              f"stopped or kept together); grace period {grace:,} env steps ({why}); rungs at "
              f"{', '.join(f'{r:,}' for r in rungs) or 'none below the budget: nothing is stopped'}")
        if len(plan.seeds) > plan.concurrency:
            print(f"  ({len(plan.seeds)} seeds wait for each other at a rung: up to {len(plan.seeds)} trials are "
                  f"live at once, {plan.concurrency} running)")
    print(f"  MLflow: {infra.tracking_uri}  experiment '{sweep.experiment}'")
    print(f"  Tune results: {plan.storage}/{plan.name}{'  (resuming)' if infra.resume else ''}")
    if plan.optuna_storage:
        print(f"  Optuna study '{plan.name}': {plan.optuna_storage}  (optuna-dashboard {plan.optuna_storage})")
    print(f"  browse: mlflow ui --backend-store-uri {infra.tracking_uri}", flush=True)


def one_line(text: str, limit: int = 600) -> str:
    """An error as one line of at most ``limit`` characters, whatever it quotes (a user's exception
    included): the messages are written short, this is the guarantee."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                              cwd=Path(__file__).parent).stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def main(argv=None) -> int:
    args = parse_args(argv)
    # RLlib warns once per process that LAC runs on the new API stack (it is built for it): noise
    # above the plan. Trials run in other processes, where RLlib's own logging is untouched.
    logging.getLogger("ray.rllib.algorithms.algorithm_config").setLevel(logging.ERROR)
    try:
        plan = make_plan(args)
        sweep_dir = Path(plan.storage) / plan.name
        if sweep_dir.resolve().parent != Path(plan.storage).resolve():  # a safe name cannot; a link might
            raise ValueError(f"sweep {plan.name!r}: its directory {sweep_dir} resolves outside --storage "
                             f"{plan.storage}; accepted: a name whose directory lies in --storage")
        if args.resume and not (sweep_dir / SWEEP_FILE).exists():
            raise ValueError(f"--resume: no sweep named {plan.name!r} under {plan.storage}")
        if args.resume:
            diff = resume_differences(sweep_dir, plan)
            if diff:
                raise ValueError(f"--resume: sweep {plan.name!r} was started with other settings: "
                                 f"{'; '.join(diff)}. Resume with the original ones, or start a new --name")
        # A directory without a record or Tune state is a start that failed early: startable.
        started = (sweep_dir / SWEEP_FILE).exists() or any(sweep_dir.glob("experiment_state*.json"))
        if not args.resume and started:
            raise ValueError(f"a sweep named {plan.name!r} exists under {plan.storage}; pass --resume or --name")
    except ValueError as e:
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 2
    lock = None
    if "://" not in plan.storage:  # object stores have no atomic create (sweeps/lock.py)
        lock = DriverLock(sweep_dir)
        try:
            lock.acquire()
        except SweepLocked as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
    else:
        print(f"note: no driver lock on {plan.storage}: do not run this sweep from two drivers at once",
              file=sys.stderr)
    try:
        print_plan(plan)
        from sweeps.sweep import run_sweep

        rc = run_sweep(plan, sweep_dir, git_commit())
    finally:
        if lock is not None:
            lock.release()
    if rc == 0 and plan.confirm:
        rc = run_confirmation(plan, sweep_dir, git_commit())
    return rc


def run_confirmation(plan: Plan, sweep_dir: Path, commit: str) -> int:
    """``--confirm-top``: the finished sweep's K best feasible configurations (read back from MLflow,
    ranked by the lower end of their return interval) rerun beside the default on fresh seeds, as
    the sweep NAME-confirm with its own parent run, whose note says whether each held up."""
    import json

    from sweeps import confirm
    from sweeps.report import summarize
    from sweeps.results import sweep_results
    from sweeps.sweep import run_sweep
    from sweeps.tracking import SweepTracker

    k, seeds, budget = plan.confirm
    fields = confirm.varied_fields(plan.sweep)
    tracker = SweepTracker(plan.tracking_uri, plan.experiment)
    parent = json.loads((sweep_dir / SWEEP_FILE).read_text())["parent_run_id"]
    trials, _ = sweep_results(tracker, parent, tuple(fields))
    fields_of = {r["config"]: {f: r[f] for f in fields if f in r and not _missing(r[f])}
                 for r in trials.to_dict("records")}
    top = confirm.winners(summarize(trials), fields_of, k) if len(trials) else []
    if not top:
        print("confirmation: no feasible configuration other than the default to confirm", flush=True)
        return 0
    name = f"{plan.name}-confirm"
    # The baselines the sweep ran (besides its own algorithm) rerun at their defaults beside the winners.
    baselines = tuple(a for a in dict.fromkeys(trials["algo"]) if a not in plan.sweep.algo and a != DEFAULT_ALGO)
    cfile = confirm.confirmation_file(plan.sweep, top, seeds, budget, name, baselines)
    cdir = Path(plan.storage) / name
    infra = dataclasses.replace(plan.infra, resume=(cdir / SWEEP_FILE).exists())
    cplan = dataclasses.replace(plan_sweep(cfile, "confirm", infra), confirms=tuple(top))
    print(f"confirmation of {plan.name}: its {len(top)} best feasible configuration(s) on seeds "
          f"{cplan.seeds[0]}..{cplan.seeds[-1]}", flush=True)
    print_plan(cplan)
    tracker.client.set_tag(parent, "lac.confirmed_by", name)
    lock = DriverLock(cdir)
    lock.acquire()
    try:
        return run_sweep(cplan, cdir, commit)
    finally:
        lock.release()


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and v != v)


if __name__ == "__main__":
    sys.exit(main())
