"""Single-run trainer: ``python -m lac_rllib.train --task ID --timesteps N --seed S --output DIR``.

Prints one progress line per iteration and, as the last line of stdout, one JSON object with
the final metrics and the checkpoint path. Every argument is checked before Ray starts.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import sys
import time

from lac_rllib.config import FIELD_NAMES, LACConfig, field_docs
from lac_rllib.tasks import known_tasks


def parse_sets(pairs: list[str]) -> dict:
    """``["temperature=1e-4", "actor_hidden=(64, 64)"]`` → dict; bad names list the accepted ones."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        name = name.strip()
        if not sep:
            raise ValueError(f"--set {pair!r}: expected field=value")
        if name not in FIELD_NAMES:
            raise ValueError(f"--set: unknown LAC config field {name!r}; accepted: {', '.join(sorted(FIELD_NAMES))}")
        try:
            out[name] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[name] = raw  # plain strings such as informative / next
    return out


def build_config(task: str, seed: int, sets: dict, num_env_runners: int = 0,
                 timesteps: int | None = None) -> LACConfig:
    """The LACConfig a run of ``timesteps`` env steps uses (validated; no Ray needed).

    The budget is the horizon of the learning-rate decay unless ``sets`` names another.
    """
    if timesteps is not None:
        sets = {"total_env_steps": int(timesteps), **sets}
    config = LACConfig().task(task).training(**sets).debugging(seed=seed)
    config.env_runners(num_env_runners=num_env_runners)
    config.validate()
    return config


def _fmt(x) -> str:
    return "nan" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3g}"


def train(config: LACConfig, timesteps: int, output: str, *, log=print) -> dict:
    """Train until ``timesteps`` env steps, checkpoint into ``output``, return the summary."""
    from ray.rllib.core import DEFAULT_MODULE_ID

    from lac_rllib.algorithm import COST_LIMIT, ENV_STEPS, EPISODE_COST, EPISODE_RETURN, FEASIBLE, NU
    from lac_rllib.learner import REPORTED_KEYS
    from lac_rllib.tasks.versions import runtime_versions

    os.makedirs(output, exist_ok=True)
    with open(os.path.join(output, "config.json"), "w") as f:
        json.dump({"task": config.task_id, "seed": config.seed, **config.lac_params()}, f, indent=2, default=str)
    algo = config.build_algo()
    start, result = time.time(), {}
    try:
        with open(os.path.join(output, "progress.jsonl"), "a") as progress:
            while not result or result[ENV_STEPS] < timesteps:
                result = algo.train()
                row = {k: float(result[k]) for k in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT, FEASIBLE, NU, ENV_STEPS)}
                learner = result.get("learners", {}).get(DEFAULT_MODULE_ID, {})
                row.update({k: float(learner[k]) for k in REPORTED_KEYS if k in learner})
                row["iteration"], row["time_s"] = int(result["training_iteration"]), time.time() - start
                progress.write(json.dumps(row) + "\n")
                progress.flush()  # a run killed mid-way keeps every finished iteration
                log(f"iter {row['iteration']:4d}  steps {int(row[ENV_STEPS]):8d}  return {_fmt(row[EPISODE_RETURN]):>8}"
                    f"  cost {_fmt(row[EPISODE_COST]):>7} / {_fmt(row[COST_LIMIT])}  nu {_fmt(row[NU]):>7}"
                    f"  {row['time_s']:7.1f}s", flush=True)
        checkpoint = algo.save_to_path(os.path.abspath(os.path.join(output, "checkpoint")))
    finally:
        algo.stop()
    return {**{k: row[k] for k in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT, NU)},
            "feasible": bool(row[FEASIBLE]), "env_steps": int(row[ENV_STEPS]),
            "iterations": row["iteration"], "wall_time_s": round(time.time() - start, 2),
            "checkpoint": checkpoint, "task": config.task_id, "seed": config.seed,
            "versions": runtime_versions()}


def main(argv: list[str] | None = None) -> int:
    docs = field_docs()
    parser = argparse.ArgumentParser(
        prog="lac-train", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="LAC fields for --set:\n" + "\n".join(f"  {k}: {docs.get(k, '')}" for k in sorted(FIELD_NAMES)),
    )
    parser.add_argument("--task", default="lac/PointHazard-v0", help=f"one of: {', '.join(known_tasks())}")
    parser.add_argument("--timesteps", type=int, required=True, help="env steps to train for (>= 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", required=True, help="directory for the checkpoint and logs")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="override a LAC config field")
    parser.add_argument("--num-env-runners", type=int, default=0, help="remote env runners (0 = sample in the driver)")
    args = parser.parse_args(argv)
    try:
        if args.timesteps < 1:
            raise ValueError(f"--timesteps {args.timesteps} is invalid; accepted: an integer >= 1")
        if args.num_env_runners < 0:
            raise ValueError(f"--num-env-runners {args.num_env_runners} is invalid; accepted: an integer >= 0")
        config = build_config(args.task, args.seed, parse_sets(args.set), args.num_env_runners, args.timesteps)
    except ValueError as e:
        parser.exit(2, f"lac-train: error: {e}\n")
    import ray

    ray.init(num_cpus=max(2, args.num_env_runners + 1), include_dashboard=False, log_to_driver=False,
             configure_logging=True, logging_level="ERROR")
    summary = train(config, args.timesteps, args.output)
    print(json.dumps(summary, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
