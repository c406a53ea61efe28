"""Single-run trainer: ``python -m lac_rllib.train --task ID --timesteps N --seed S --output DIR``
(``--algo NAME`` trains another algorithm of the registry instead: lac_rllib/algorithms/registry.py;
``--algo mypkg.safe_algo`` a user's own, named by its module's import path).

Prints one progress line per iteration and, as the last line of stdout, one JSON object with
the final metrics and the checkpoint path. Every argument is checked before Ray starts.
``progress.jsonl`` gets one line per iteration as it ends; a checkpoint (replay buffer included)
is written every ``--checkpoint-every`` iterations, and ``--resume`` continues a stopped run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time

from lac_rllib.algorithms import registry
from lac_rllib.algorithms.lac.config import FIELDS as LAC_FIELDS
from lac_rllib.constrained.metrics import (
    COST_LIMIT,
    ENV_STEPS,
    EPISODE_COST,
    EPISODE_RETURN,
    FEASIBLE,
    ITERATION,
    NU,
    iteration_row,
)
from lac_rllib.tasks import known_tasks


def _fmt(x) -> str:
    return "nan" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3g}"


CHECKPOINT, PROGRESS, CONFIG = "checkpoint", "progress.jsonl", "config.json"


#: The key of config.json that holds what rule-valued fields resolved to (SafeTaskConfig.resolved).
RESOLVED = "resolved"


def run_config(config) -> dict:
    """What ``config.json`` in a run's output holds (and what ``--resume`` compares)."""
    return json.loads(json.dumps({"task": config.task_id, "seed": config.seed,
                                  registry.ALGO_FIELD: config.ALGO, **config.params(),
                                  RESOLVED: config.resolved()}, default=str))


def resumable_checkpoint(output: str) -> str | None:
    """The run's latest complete checkpoint. ``_save`` removes the old one only after the new one
    is written, so a lone ``checkpoint.new`` is complete."""
    for name in (CHECKPOINT, CHECKPOINT + ".new"):
        path = os.path.abspath(os.path.join(output, name))
        if os.path.isdir(path):
            return path
    return None


def _lr_horizon(params: dict):
    """The lr decay's horizon a run's config.json implies (None: no decay)."""
    if params.get("lr_schedule", params.get("policy_lr_schedule")) in ("constant", None):
        return None  # no decay (SAC-Lag has no schedule)
    horizon = params.get("lr_decay_horizon")
    return horizon if horizon is not None else params.get("total_env_steps")


def check_output(output: str, config, resume: bool) -> None:
    """A writable directory that holds no other run (checked before Ray starts)."""
    try:
        os.makedirs(output, exist_ok=True)
    except OSError as e:
        raise ValueError(f"--output {output} cannot be created ({e.strerror}); "
                         "accepted: a writable directory") from None
    if not os.access(output, os.W_OK | os.X_OK):
        raise ValueError(f"--output {output} is not writable; accepted: a writable directory")
    progress = os.path.join(output, PROGRESS)
    if not resume:
        if os.path.exists(progress):
            raise ValueError(f"--output {output} holds a run already ({PROGRESS}); pass --resume to continue it "
                             "or choose another --output")
        return
    if resumable_checkpoint(output) is None or not os.path.exists(os.path.join(output, CONFIG)):
        raise ValueError(f"--resume: no checkpoint in {output} to continue from")
    with open(os.path.join(output, CONFIG)) as f:
        old = {registry.ALGO_FIELD: registry.DEFAULT_ALGO, **json.load(f)}  # runs before 0.2 name no algo: LAC
    new = run_config(config)
    if RESOLVED not in old:  # runs that recorded no resolution: their explicit values were it
        new.pop(RESOLVED)
    speed = registry.speed_fields(new[registry.ALGO_FIELD])
    diff = sorted(k for k in old.keys() | new.keys() if old.get(k) != new.get(k) and k not in speed)
    if "total_env_steps" in diff and _lr_horizon(old) == _lr_horizon(new):
        # The budget shapes training only through the lr decay's horizon: with lr_decay_horizon
        # set (the Safety-Gym and MuJoCo presets) a run may be carried on to a larger budget.
        diff.remove("total_env_steps")
    if diff:
        raise ValueError("--resume: the run in {} was started with other settings: {}".format(
            output, ", ".join(f"{k}={old.get(k)!r} (now {new.get(k)!r})" for k in diff)))
    from lac_rllib.evaluation import CheckpointError, read_metadata

    try:  # a checkpoint another lac-rllib version wrote names classes this one may not have
        read_metadata(resumable_checkpoint(output))
    except CheckpointError as e:
        raise ValueError(f"--resume: {e}") from None


def _save(algo, output: str) -> str:
    final = os.path.abspath(os.path.join(output, CHECKPOINT))
    tmp = final + ".new"
    shutil.rmtree(tmp, ignore_errors=True)
    algo.save_to_path(tmp)
    shutil.rmtree(final, ignore_errors=True)  # a kill from here on leaves checkpoint.new, complete
    os.rename(tmp, final)
    return final


def train(config, timesteps: int, output: str, *, log=print, checkpoint_every: int = 0,
          resume: bool = False) -> dict:
    """Train until ``timesteps`` env steps, checkpoint into ``output``, return the summary.

    Checkpoints (replay buffer included, ``store_replay_buffer``) every ``checkpoint_every``
    iterations (0: only at the end). ``resume`` restores the latest one and continues: iterations
    after it are dropped from ``progress.jsonl`` and trained again. A run whose latest checkpoint
    already reached ``timesteps`` is finished: nothing is trained, and its summary is returned.
    """
    from lac_rllib.tasks.versions import runtime_versions

    os.makedirs(output, exist_ok=True)
    check_output(output, config, resume)
    with open(os.path.join(output, CONFIG), "w") as f:
        json.dump(run_config(config), f, indent=2)
    algo = config.build_algo()
    start, rows = time.time(), []
    try:
        if resume:
            checkpoint = resumable_checkpoint(output)
            algo.restore_from_path(checkpoint)
            with open(os.path.join(output, PROGRESS)) as f:
                rows = [r for r in map(json.loads, filter(str.strip, f)) if r[ITERATION] <= algo.iteration]
            start -= rows[-1]["time_s"] if rows else 0.0
            log(f"resumed at iteration {algo.iteration} from {checkpoint}")
        row = rows[-1] if rows else None
        if row is not None and row[ENV_STEPS] >= timesteps:
            # The checkpoint is the one written after the last iteration: the run is complete.
            log(f"the run in {output} is finished: {int(row[ENV_STEPS])} of {timesteps} env steps at iteration "
                f"{row[ITERATION]}; nothing to train")
            wall_time_s = row["time_s"]
        else:
            with open(os.path.join(output, PROGRESS), "w") as progress:
                progress.writelines(json.dumps(r) + "\n" for r in rows)
                progress.flush()
                while row is None or row[ENV_STEPS] < timesteps:
                    row = {**iteration_row(algo.train(), algo.config.REPORTED_KEYS), "time_s": time.time() - start}
                    progress.write(json.dumps(row) + "\n")
                    progress.flush()  # a run killed mid-way keeps every finished iteration
                    log(f"iter {row[ITERATION]:4d}  steps {int(row[ENV_STEPS]):8d}  return "
                        f"{_fmt(row[EPISODE_RETURN]):>8}  cost {_fmt(row[EPISODE_COST]):>7} / {_fmt(row[COST_LIMIT])}"
                        f"  nu {_fmt(row[NU]):>7}  {row['time_s']:7.1f}s", flush=True)
                    if checkpoint_every and row[ITERATION] % checkpoint_every == 0 and row[ENV_STEPS] < timesteps:
                        _save(algo, output)
            checkpoint = _save(algo, output)
            wall_time_s = time.time() - start
    finally:
        algo.stop()
    return {**{k: row[k] for k in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT, NU)},
            FEASIBLE: bool(row[FEASIBLE]), ENV_STEPS: int(row[ENV_STEPS]),
            "iterations": row[ITERATION], "wall_time_s": round(wall_time_s, 2),
            "checkpoint": checkpoint, "task": config.task_id, "seed": config.seed,
            "versions": runtime_versions()}


def start_ray(num_cpus: int, attempts: int = 3) -> None:
    """A local Ray instance. Ray gives its raylet a fixed 30 s to register; on a machine whose
    cores are taken (several niced runs at once) that fails now and then, so try again."""
    import ray

    for attempt in range(1, attempts + 1):
        try:
            ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False,
                     configure_logging=True, logging_level="ERROR")
            return
        except Exception as e:  # Ray raises a bare Exception for this
            if "timed out during startup" not in str(e) or attempt == attempts:
                raise
            print(f"lac-train: Ray's node did not start in time (attempt {attempt}/{attempts}); retrying",
                  file=sys.stderr, flush=True)
            ray.shutdown()
            time.sleep(10 * attempt)


def main(argv: list[str] | None = None) -> int:
    docs = LAC_FIELDS.docs()
    parser = argparse.ArgumentParser(
        prog="lac-train", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="LAC fields for --set:\n" + "\n".join(
            f"  {k}: {docs.get(k, '')} Accepted: {LAC_FIELDS.ranges[k].text}." for k in sorted(LAC_FIELDS.names))
        + f"\n\nThe other algorithms' fields (--algo {registry.algos_text()}): docs/config.md.",
    )
    parser.add_argument("--algo", default=registry.DEFAULT_ALGO,
                        help=f"the algorithm: {registry.algos_text()} (default lac), or the import path of your own "
                             "algorithm's module, e.g. mypkg.safe_algo (docs/baselines.md)")
    parser.add_argument("--task", default="lac/PointHazard-v0", help=f"one of: {', '.join(known_tasks())}")
    parser.add_argument("--timesteps", type=int, required=True, help="env steps to train for (>= 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", required=True, help="directory for the checkpoint and logs")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a field of the algorithm's config")
    parser.add_argument("--num-env-runners", type=int, default=0, help="remote env runners (0 = sample in the driver)")
    parser.add_argument("--cpus", type=int, default=1,
                        help="CPUs of the run: as many env runners sample and as many torch threads update, the same "
                             "algorithm (num_envs_per_env_runner must split evenly over them)")
    parser.add_argument("--checkpoint-every", type=int, default=5,
                        help="iterations between checkpoints, replay buffer included (0 = only at the end)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in --output from its latest checkpoint (same settings)")
    args = parser.parse_args(argv)
    try:
        if args.timesteps < 1:
            raise ValueError(f"--timesteps {args.timesteps} is invalid; accepted: an integer >= 1")
        if args.checkpoint_every < 0:
            raise ValueError(f"--checkpoint-every {args.checkpoint_every} is invalid; accepted: an integer >= 0")
        if args.num_env_runners < 0:
            raise ValueError(f"--num-env-runners {args.num_env_runners} is invalid; accepted: an integer >= 0")
        try:  # a user's module is imported and checked here, from the Python path or the working
            # directory (which Ray's workers share)
            registry.check_algo(args.algo, (os.getcwd(),))
        except ValueError as e:
            raise ValueError(f"--algo: {e}") from None
        config = registry.build_config(args.algo, args.task, args.seed, registry.parse_sets(args.algo, args.set),
                                       args.num_env_runners, args.timesteps, cpus=args.cpus)
        check_output(args.output, config, args.resume)
    except ValueError as e:
        parser.exit(2, f"lac-train: error: {e}\n")
    start_ray(num_cpus=max(2, args.num_env_runners + 1, args.cpus))
    summary = train(config, args.timesteps, args.output, checkpoint_every=args.checkpoint_every, resume=args.resume)
    print(json.dumps(summary, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
