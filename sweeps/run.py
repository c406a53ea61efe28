"""The sweep service: ``python sweeps/run.py --space ablation`` (Ray Tune + Optuna, tracked in MLflow);
``lac-sweep calibrate --task ID`` proposes a ladder of cost limits for a task (sweeps/calibrate.py);
``lac-sweep registry`` lists the tuned configurations (sweeps/tuned_registry.py); a sweep file with
``tune:`` runs a tuned comparison (sweeps/tuned.py).

Every argument is checked, and the plan printed, before Ray starts. One MLflow parent run per
sweep, one child run per trial; the Tune experiment lives in ``--storage``/``--name`` so that
``--resume`` (same arguments) continues a sweep whose driver was killed.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
from pathlib import Path
from typing import Protocol

from lac_rllib.algorithms.registry import algos_text
from sweeps import spaces, sweep_file
from sweeps.estimate import duration_text
from sweeps.infra import Infra, check_address, check_shared, check_storage
from sweeps.lock import SweepLocked, sweep_lock
from sweeps.plan import MAX_TRIALS, Plan, check_confirm, confirmation_plan, plan_sweep
from sweeps.record import parent_run_id
from sweeps.resolve import module_search_dirs, resolve_sweep
from sweeps.tracking import CONFIRMED_BY_TAG, SweepTracker, check_reachable, default_tracking_uri

#: The command's name in its help and errors: the console script, or the file as ``python`` ran it.
PROG = "lac-sweep" if Path(sys.argv[0]).name == "lac-sweep" else "sweeps/run.py"


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


def _limits(text: str) -> list:
    """``--cost-limits 0,2,4.5`` as numbers (the sweep file's schema checks them as it checks its own)."""
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text} is invalid; accepted: numbers >= 0 joined by commas, "
                                         "e.g. 0,2,4") from None


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
                   help="the first seed (default 0); a confirmation by hand starts 1000 past the search's "
                        "largest, or it reruns the search's env streams (sweeps/seeds.py)")
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
                        "return interval) beside the default on fresh seeds (sweeps/reports/confirm.py)")
    p.add_argument("--confirm-seeds", type=_int_at_least(1), default=None, metavar="N",
                   help="seeds of the confirmation (default: the sweep's count, at least 3)")
    from sweeps.reports.confirm import CONFIRM_BY

    p.add_argument("--confirm-by", default="return", metavar="|".join(CONFIRM_BY),
                   help="how the confirmation picks its winners: the lower end of the return interval (default), "
                        "or over a ladder with its frontier the least worst or mean regret R*(b) - R(b)")
    p.add_argument("--confirm-budget", type=_budget, default=None, metavar="BUDGET",
                   help="the confirmation's budget: the sweep's (default) or a larger one")
    p.add_argument("--cost-limits", type=_limits, default=None, metavar="B1,B2,...",
                   help="a ladder of cost limits: every configuration runs at each (the sweep file's cost_limits; "
                        "lac-sweep calibrate --task ID proposes one)")
    p.add_argument("--tune", type=_int_at_least(1), default=None, metavar="N",
                   help="a tuned comparison of the sweep's algorithms (compare, table1, ...): each searched over its "
                        "own space with N samples (the sweep file's tune.num_samples; docs/sweeps.md)")
    p.add_argument("--tune-seeds", type=_int_at_least(1), default=None, metavar="K",
                   help="seeds per sampled configuration of a tuned comparison (tune.seeds; default 3); its "
                        "fresh seeds: --confirm-seeds (tune.confirm_seeds, default 5)")
    p.add_argument("--registry", default=None, metavar="DIR",
                   help="the registry of tuned configurations a tuned comparison writes and preset: tuned reads "
                        "(default: the repository's tuned/; lac-sweep registry lists it)")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="set a field in every trial (the swept value wins); e.g. nu_max_adaptive=False; "
                        f"algo={algos_text('|')} picks the algorithm (fields: docs/config.md), or "
                        "algo=mypkg.safe_algo your own algorithm's module (docs/baselines.md)")
    return p.parse_args(argv)


class Job(Protocol):
    """What lac-sweep runs: a sweep's Plan (sweeps/plan.py) or a tuned comparison's TunedPlan
    (sweeps/tuned.py, one per task)."""

    def check(self) -> None:
        """Its sweeps' directories checked before Ray starts (a ValueError says what is wrong)."""

    def run(self, run_plan) -> int:
        """Run it, each sweep by ``run_plan`` (:func:`run_plan`): the exit code."""


def make_plan(args) -> list[Job]:
    """The one pass from the command line to what runs: file and flags → the resolved sweep
    (sweeps/resolve.py) → its trials with their full configs (``spaces.trial_params``) → the
    estimate and where it goes (sweeps/plan.py ``plan_sweep``): one Plan; a sweep file with
    ``tune:`` one TunedPlan per task. Every input is checked here, before Ray starts."""
    sweep, space, origin = resolve_sweep(args)
    address = args.address or os.environ.get("RAY_ADDRESS") or None
    infra = Infra(address=address, address_from="--address" if args.address else "RAY_ADDRESS" if address else None,
                  tracking_uri=args.tracking_uri or default_tracking_uri(), storage=args.storage,
                  resume=args.resume, max_failures=args.max_failures, optuna_seed=args.optuna_seed,
                  optuna_storage=args.optuna_storage, registry=args.registry)
    check_address(address, infra.address_from)
    check_storage(args.storage)
    if address not in (None, "local"):
        check_shared(infra.tracking_uri, args.storage, infra.address_from)
    check_reachable(infra.tracking_uri)
    if sweep.tune is not None:  # every algorithm searched at the same budget, then confirmed together
        if args.confirm_top:
            raise ValueError("--confirm-top with tune: a tuned comparison confirms every algorithm's winners "
                             "itself; accepted: tune.top and tune.confirm_seeds in the sweep file")
        from sweeps.tuned import make_tuned_plans

        return make_tuned_plans(sweep, space, infra, module_search_dirs(args), origin, args.max_trials,
                                registry=args.registry)
    plan = plan_sweep(sweep, space, infra, module_search_dirs(args), origin, max_trials=args.max_trials)
    if args.confirm_by != "return" and not args.confirm_top:
        raise ValueError(f"--confirm-by {args.confirm_by} without --confirm-top; accepted: --confirm-top K "
                         f"--confirm-by {args.confirm_by}")
    if args.confirm_top:
        plan = dataclasses.replace(plan, confirm=check_confirm(plan, args.confirm_top, args.confirm_seeds,
                                                               args.confirm_budget, args.confirm_by))
    return [plan]


def print_plan(plan: Plan) -> None:
    """The plan as the user reads it before Ray starts: what runs, what it costs, where it goes."""
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
    if plan.pbt is not None:  # population-based training (sweeps/pbt.py)
        pbt = sweep.pbt
        subs = len(plan.pbt)
        print(f"  trials: {plan.n_trials}  (a population of {pbt.members} members, one seed each: {seed_text}; "
              f"{pbt.members * plan.timesteps:,} env steps in all)")
        print(f"  pbt: {'sub-populations exploiting' if subs > 1 else 'members exploit'} every "
              f"{' / '.join(f'{i:,}' for i in plan.pbt)} env steps"
              + (f" (x{pbt.growth:g} after each)" if pbt.growth != 1 else "")
              + (", the best of a slower one migrating to the next faster" if subs > 1 and pbt.migrate else "")
              + f"; the bottom {pbt.quantile:.0%} copy a top member and perturb {', '.join(sweep.search)}; "
              f"ranked by the one feasibility rule on their last {pbt.window} iterations")
    else:
        print(f"  trials: {plan.n_trials}  ({what}{len(seeds)} seed(s) per configuration: {seed_text})")
    if sweep.is_search and plan.pbt is None:  # how many of the samples the searcher steers (sweeps/search.py)
        from sweeps.search import configurations_at_once, search_text

        at_once = configurations_at_once(plan.concurrency, len(seeds))
        print(f"  search: {search_text(sweep.searcher, sweep.num_samples, at_once)}")
        if sweep.env_steps_budget is not None:  # sweeps/sweep.py EnvStepBudget
            print(f"  env steps: at most {sweep.env_steps_budget:,} spent in all (the samples are drawn while a whole "
                  f"configuration more fits; {sweep.num_samples} is an upper bound)")
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
    backends = env_backends(plan)
    if backends:
        print(f"  env backend: {backends}")
    print(f"  estimated wall time: {duration_text(plan.estimated_wall_s)} at {plan.concurrency} trials at a time, "
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


def env_backends(plan: Plan) -> str:
    """Which backend each task's envs step on (``env_backend``: lac_rllib/tasks/batched_navigation.py),
    read from the trials' env fingerprints; empty where no task of the sweep has a batched one."""
    per_task: dict[str, set] = {}
    for fp in plan.env_fingerprints.values():
        per_task.setdefault(fp["task"], set()).add(fp.get("env_backend"))
    if not any(b for bs in per_task.values() for b in bs):
        return ""
    parts = [f"{task} {' and '.join(sorted(b or 'stock' for b in bs))}" + ("" if any(bs) else " (no batched one)")
             for task, bs in per_task.items()]
    return "; ".join(parts) if len(parts) <= 4 else (
        f"{sum('batched' in p for p in parts)} of {len(parts)} tasks batched, the others stock")


def one_line(text: str, limit: int = 600) -> str:
    """An error as one line of at most ``limit`` characters, whatever it quotes (a user's exception
    included): the messages are written short, this is the guarantee."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["calibrate"]:  # lac-sweep calibrate: a task's cost range and a ladder of limits
        from sweeps import calibrate

        return calibrate.main(argv[1:])
    if argv[:1] == ["registry"]:  # lac-sweep registry [DIR]: the tuned configurations
        from sweeps.tuned_registry import DEFAULT_REGISTRY, listing

        print(listing(Path(argv[1]) if len(argv) > 1 else DEFAULT_REGISTRY))
        return 0
    args = parse_args(argv)
    # RLlib warns once per process that LAC runs on the new API stack (it is built for it): noise
    # above the plan. Trials run in other processes, where RLlib's own logging is untouched.
    logging.getLogger("ray.rllib.algorithms.algorithm_config").setLevel(logging.ERROR)
    try:
        jobs = make_plan(args)
        for job in jobs:  # every sweep's directory checked before Ray starts
            job.check()
    except ValueError as e:
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 2
    for job in jobs:
        rc = job.run(run_plan)
        if rc != 0:
            return rc
    return 0


def run_plan(plan: Plan, sweep_dir: Path) -> int:
    """Run ``plan`` into ``sweep_dir`` (:func:`run_locked`), then its confirmation where it asks for
    one (``--confirm-top``): the first non-zero exit code, else 0."""
    rc = run_locked(plan, sweep_dir)
    return run_confirmation(plan, sweep_dir) if rc == 0 and plan.confirm else rc


def run_locked(plan: Plan, sweep_dir: Path) -> int:
    """Print ``plan`` and run it into ``sweep_dir``, holding the sweep's driver lock (sweeps/lock.py):
    the run's exit code, or 2 with a one-line error where another driver holds the sweep."""
    try:
        with sweep_lock(sweep_dir, plan.storage):
            print_plan(plan)
            # Ray is imported here, after the plan is printed: the checks before answer without it.
            from sweeps.record import git_commit
            from sweeps.sweep import run_sweep

            return run_sweep(plan, sweep_dir, git_commit())
    except SweepLocked as e:  # raised on entering the lock, before the plan is printed
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2


def run_confirmation(plan: Plan, sweep_dir: Path) -> int:
    """``--confirm-top``: the finished sweep's confirmation (sweeps/plan.py ``confirmation_plan``),
    printed, then run as the sweep NAME-confirm with its own parent run, whose note says whether
    each winner held up; the sweep's parent run names it."""
    confirmation = confirmation_plan(plan)
    if confirmation is None:
        print("confirmation: no feasible configuration other than the default to confirm", flush=True)
        return 0
    by = (*plan.confirm, "return")[3]
    how = "best feasible" if by == "return" else f"least {by.replace('-', ' ')}"
    names = ", ".join(w.get("name", w["config"]) for w in confirmation.confirms)
    print(f"confirmation of {plan.name}: its {len(confirmation.confirms)} {how} configuration(s) ({names}) on seeds "
          f"{confirmation.seeds[0]}..{confirmation.seeds[-1]}", flush=True)
    SweepTracker(plan.tracking_uri, plan.experiment).client.set_tag(parent_run_id(sweep_dir), CONFIRMED_BY_TAG,
                                                                   confirmation.name)
    return run_locked(confirmation, Path(confirmation.storage) / confirmation.name)


if __name__ == "__main__":
    sys.exit(main())
