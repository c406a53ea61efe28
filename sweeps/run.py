"""The sweep service: ``python sweeps/run.py --space ablation`` (Ray Tune + Optuna, tracked in MLflow).

Every argument is checked, and the plan printed, before Ray starts. One MLflow parent run per
sweep, one child run per trial; the Tune experiment lives in ``--storage``/``--name`` so that
``--resume`` (same arguments) continues a sweep whose driver was killed.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

from sweeps import spaces
from sweeps.lock import DriverLock, SweepLocked
from sweeps.plan import Plan
from sweeps.record import SWEEP_FILE, resume_differences
from sweeps.tracking import check_reachable, default_tracking_uri

# The plan's estimate, per preset: env steps per second of one trial on 1 CPU without the chain,
# and chain seconds per env step and per Langevin step (calibration: docs/sweeps.md).
RATE = {"tiny": 405.0, "safety_gym": 377.0, "mujoco": 185.0}
CHAIN_S_PER_STEP = {"tiny": 4.1e-5, "safety_gym": 1.37e-4, "mujoco": 5.3e-4}
STARTUP_S = 15.0
# A baseline's update seconds per env step (SAC-Lag: per update per env step) at the tiny sizes.
UPDATE_S_PER_STEP = {"ppo_lag": 2e-4, "sac_lag": 2e-3}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="sweeps/run.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--space", required=True, choices=spaces.SPACES, help="which search space")
    p.add_argument("--task", default=None, help=f"task id (default {spaces.DEFAULT_TASK}; smoke: {spaces.SMOKE_TASK}; "
                                                 "paper: all paper tasks)")
    p.add_argument("--budget", default="quick", choices=list(spaces.BUDGETS),
                   help="; ".join(f"{k}: {b.describe()}" for k, b in spaces.BUDGETS.items()))
    p.add_argument("--seeds", type=int, default=3, help="seeds per configuration (search: per Optuna sample)")
    p.add_argument("--num-samples", type=int, default=20, help="Optuna samples, i.e. configurations (search space)")
    p.add_argument("--max-concurrent", type=int, default=None, help="trials at once (default: CPUs / cpus-per-trial)")
    p.add_argument("--cpus-per-trial", type=int, default=1,
                   help="CPUs per trial: as many env runners sample and as many torch threads update")
    p.add_argument("--scheduler", choices=("none", "asha"), default="none")
    p.add_argument("--address", default=None, help="Ray cluster address (host:port or auto); default: local Ray")
    p.add_argument("--tracking-uri", default=None,
                   help="MLflow tracking URI (default: sqlite store in the working dir)")
    p.add_argument("--experiment", default="lac-sweeps", help="MLflow experiment name")
    p.add_argument("--storage", default="ray_results",
                   help="Tune storage path (on a cluster: an absolute path every node mounts)")
    p.add_argument("--name", default=None, help="sweep name (default: space-task-budget); --resume finds it by name")
    p.add_argument("--resume", action="store_true", help="continue the sweep of the same name")
    p.add_argument("--max-failures", type=int, default=2, help="retries of a failed trial (node loss)")
    p.add_argument("--optuna-seed", type=int, default=0, help="seed of the TPE sampler")
    p.add_argument("--optuna-storage", default=None,
                   help="Optuna storage URL of the search space's study (default: optuna.db beside a local MLflow "
                        "store, else in --storage); open it with optuna-dashboard URL")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="set a field in every trial (the swept value wins); e.g. nu_max_adaptive=False; "
                        "algo=ppo_lag|sac_lag runs a baseline (fields: docs/config.md)")
    return p.parse_args(argv)


def check_address(address: str | None) -> None:
    if address in (None, "auto", "local"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--address {address!r}: accepted: auto, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as e:
        raise ValueError(f"--address {address}: cannot connect ({e}); is `ray start --head` running there?") from None


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


def check_shared(uri: str, storage: str) -> None:
    """On a cluster every trial runs on some node: the tracking store and the storage path must
    be the same place for all of them, not one local copy per node."""
    if uri.startswith(("sqlite:", "file:")) or "://" not in uri:
        raise ValueError(f"--tracking-uri {uri} with --address: each node would write its own local store; "
                         "accepted: http(s)://HOST:PORT of an mlflow server every node reaches (docker/README.md)")
    if not storage.startswith("file://") and not os.path.isabs(storage):
        raise ValueError(f"--storage {storage} with --address: a relative path is a different directory on every "
                         "node; accepted: an absolute path every node mounts at the same place")


def make_plan(args) -> Plan:
    spaces.validate(args.space, args.task, args.budget, args.seeds)
    for flag in ("num_samples", "cpus_per_trial", "max_concurrent"):
        v = getattr(args, flag)
        if v is not None and v < 1:
            raise ValueError(f"--{flag.replace('_', '-')} {v} is invalid; accepted: an integer >= 1")
    sets = parse_trial_sets(args.space, args.set)
    if not args.address and args.cpus_per_trial > (os.cpu_count() or 1):
        # Tune would keep such a trial PENDING forever on the local Ray this command starts.
        raise ValueError(f"--cpus-per-trial {args.cpus_per_trial} is more than this machine's "
                         f"{os.cpu_count()} CPUs; accepted: 1..{os.cpu_count()} (or --address a larger cluster)")
    check_address(args.address)
    uri = args.tracking_uri or default_tracking_uri()
    check_storage(args.storage)
    if args.address not in (None, "local"):
        check_shared(uri, args.storage)
    check_reachable(uri)
    task = spaces.default_task(args.space, args.task)
    budget = spaces.BUDGETS[args.budget]
    # Every grid trial's LAC fields, resolved once, here (spaces.trial_params: preset < task <
    # budget < --set < swept value); a search sample is resolved in its trial the same way.
    trials = (spaces.resolve_trials(spaces.grid(args.space, task, args.seeds, args.budget), args.budget, sets)
              if args.space != "search" else None)
    from lac_rllib.constrained.cpus import check_cpus

    for params in [t.params for t in trials] if trials else [spaces.trial_params(task, args.budget, sets)]:
        check_cpus(params.get("num_envs_per_env_runner", 1), args.cpus_per_trial, "--cpus-per-trial")
    # search: each Optuna sample is trained with every seed (sweeps/sweep.py, SeedRepeater)
    n_trials = len(trials) if trials is not None else args.num_samples * args.seeds
    concurrency = min(args.max_concurrent or max(1, (os.cpu_count() or 1) // args.cpus_per_trial), n_trials)
    # A search is estimated at the fields it runs before Optuna's samples (the sampled T is not known yet).
    per_trial = ([estimate_trial_s(t.task, budget.for_task(t.task)[0], t.params, args.cpus_per_trial)
                  for t in trials] if trials else
                 [estimate_trial_s(task, budget.for_task(task)[0], spaces.trial_params(task, args.budget, sets),
                                   args.cpus_per_trial)] * n_trials)
    (timesteps,) = {budget.for_task(t.task)[0] for t in trials} if trials else {budget.for_task(task)[0]}
    name = args.name or f"{args.space}-{(task or 'paper').split('/')[-1]}-{args.budget}"
    optuna_storage = None
    if args.space == "search":
        optuna_storage = args.optuna_storage or default_optuna_storage(uri, args.storage)
        check_optuna_study(optuna_storage, name, args.resume)
    return Plan(
        space=args.space, task=task, budget=args.budget, timesteps=timesteps, trials=trials, n_trials=n_trials,
        concurrency=concurrency, sets=sets, estimated_wall_s=estimate_wall_s(per_trial, concurrency),
        estimated_cpu_h=sum(per_trial) * args.cpus_per_trial / 3600, tracking_uri=uri, experiment=args.experiment,
        name=name, storage=str(Path(args.storage.removeprefix("file://")).resolve()), optuna_storage=optuna_storage,
    )


def parse_trial_sets(space: str, pairs: list[str]) -> dict:
    """``--set FIELD=VALUE`` as the fields every trial sets, checked against each algorithm the
    sweep runs (``--set algo=NAME`` picks one; the compare space runs them all)."""
    from lac_rllib.algorithms import registry

    algo_pairs = [p for p in pairs if p.partition("=")[0].strip() == registry.ALGO_FIELD]
    field_pairs = [p for p in pairs if p not in algo_pairs]
    sets = {}
    if algo_pairs:
        if space == "compare":
            raise ValueError(f"--set {algo_pairs[-1]} with --space compare: the space runs every algorithm "
                             f"({', '.join(spaces.COMPARE_ALGOS)}); accepted: --set of fields they share")
        sets[registry.ALGO_FIELD] = registry.check_algo(algo_pairs[-1].partition("=")[2].strip())
    algos = spaces.COMPARE_ALGOS if space == "compare" else (sets.get(registry.ALGO_FIELD, registry.DEFAULT_ALGO),)
    if space in ("search", "ablation", "smoke") and algos != ("lac",):
        raise ValueError(f"--space {space} sweeps LAC's own fields (T, eta, lambda, beta); --set algo={algos[0]} is "
                         "not LAC; accepted for a baseline: --space paper or --space compare")
    for algo in algos:
        fields = registry.parse_sets(algo, field_pairs)  # a field another algorithm owns is named as such
        for name, value in fields.items():
            registry.algo_config(algo).FIELDS.check(name, value)
        sets.update(fields)
    return sets


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


def estimate_trial_s(task: str, steps: int, params: dict, cpus: int) -> float:
    """Rough wall seconds of one trial of ``steps`` env steps whose fields are ``params``
    (``spaces.trial_params``): start-up, then env steps at the preset's measured rate, plus LAC's
    chain share, which grows with T, or a baseline's update share (measured on this project's
    2-core machine)."""
    from lac_rllib.tasks import get_task

    preset = get_task(task).preset
    algo = params.get("algo", "lac")
    if algo == "lac":
        extra = CHAIN_S_PER_STEP.get(preset, 0.0) * params["langevin_steps"] * steps
    else:
        extra = UPDATE_S_PER_STEP[algo] * params.get("updates_per_env_step", 1.0) * steps
    return STARTUP_S + (steps / RATE[preset] + extra) / cpus ** 0.5


def estimate_wall_s(per_trial: list[float], concurrency: int) -> float:
    """Trials taken longest first onto ``concurrency`` slots (Tune starts them in grid order, so
    this is a floor when the longest come last)."""
    slots = [0.0] * concurrency
    for t in sorted(per_trial, reverse=True):
        slots[slots.index(min(slots))] += t
    return max(slots)


def print_plan(plan: Plan, args) -> None:
    print(f"LAC sweep '{plan.name}': space={plan.space} task={plan.task or 'all paper tasks'} "
          f"budget={plan.budget}")
    what = f"{args.num_samples} Optuna TPE samples x " if plan.trials is None else ""
    print(f"  trials: {plan.n_trials}  ({what}{args.seeds} seed(s) per configuration)")
    print(f"  env steps per trial: {plan.timesteps:,}   "
          f"concurrency: {plan.concurrency} x {args.cpus_per_trial} CPU"
          f"{'' if not args.address else ' (cluster: capped by its CPUs)'}")
    print(f"  estimated wall time: ~{plan.estimated_wall_s / 60:.0f} min, "
          f"{plan.estimated_cpu_h:.1f} CPU-hours (rough)")
    if plan.estimated_wall_s > 4 * 3600 and not args.address:
        print("  too long for one machine? the same command runs on a Ray cluster: --address HEAD:PORT "
              "(set-up: docker/README.md)")
    print(f"  MLflow: {plan.tracking_uri}  experiment '{plan.experiment}'")
    print(f"  Tune results: {plan.storage}/{plan.name}{'  (resuming)' if args.resume else ''}")
    if plan.optuna_storage:
        print(f"  Optuna study '{plan.name}': {plan.optuna_storage}  (optuna-dashboard {plan.optuna_storage})")
    print(f"  browse: mlflow ui --backend-store-uri {plan.tracking_uri}", flush=True)


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
        if args.resume and not (sweep_dir / SWEEP_FILE).exists():
            raise ValueError(f"--resume: no sweep named {plan.name!r} under {plan.storage}")
        if args.resume:
            diff = resume_differences(json.loads((sweep_dir / SWEEP_FILE).read_text()), plan, args)
            if diff:
                raise ValueError(f"--resume: sweep {plan.name!r} was started with other settings: "
                                 f"{'; '.join(diff)}. Resume with the original ones, or start a new --name")
        # A directory without a record or Tune state is a start that failed early: startable.
        started = (sweep_dir / SWEEP_FILE).exists() or any(sweep_dir.glob("experiment_state*.json"))
        if not args.resume and started:
            raise ValueError(f"a sweep named {plan.name!r} exists under {plan.storage}; pass --resume or --name")
    except ValueError as e:
        print(f"sweeps/run.py: error: {e}", file=sys.stderr)
        return 2
    lock = None
    if "://" not in plan.storage:  # object stores have no atomic create (sweeps/lock.py)
        lock = DriverLock(sweep_dir)
        try:
            lock.acquire()
        except SweepLocked as e:
            print(f"sweeps/run.py: error: {e}", file=sys.stderr)
            return 2
    else:
        print(f"note: no driver lock on {plan.storage}: do not run this sweep from two drivers at once",
              file=sys.stderr)
    try:
        print_plan(plan, args)
        from sweeps.sweep import run_sweep

        return run_sweep(plan, args, sweep_dir, git_commit())
    finally:
        if lock is not None:
            lock.release()


if __name__ == "__main__":
    sys.exit(main())
