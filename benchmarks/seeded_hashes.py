"""Hashes of seeded runs, one per algorithm: the proof that a refactor changed nothing an agent learns.

    python benchmarks/seeded_hashes.py --task SafetyPointGoal1-v0 --iterations 2
    python benchmarks/seeded_hashes.py --task lac/PointHazard-v0 --iterations 3 --algos ppo_lag,cpo
    python benchmarks/seeded_hashes.py --algos lac,ppo_lag --set env_backend=stock   # the other backend
    PYTHONPATH=TREE python benchmarks/seeded_hashes.py ...   # the code unpacked at another revision

Each algorithm of the registry is built at its task preset from one seed (``--seed``), trains
``--iterations`` iterations in this process (no env runners, Ray with one CPU), and is hashed:
every tensor of every RLModule's state (ν and the critics included), the state of every
optimizer, and each iteration's reported row (return, cost, ν, losses). Two revisions that learn
the same print the same lines. The ``--timesteps`` horizon sets the lr decays, as a real run's does.
Prints one ``algo  hash`` line per algorithm, then the wall seconds it took.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time

import numpy as np
import torch


def _digest(h, value) -> None:
    """Feed ``value`` (nested dicts / lists of tensors, arrays and numbers) into ``h`` in key order."""
    if isinstance(value, dict):
        for k in sorted(value, key=str):
            h.update(str(k).encode())
            _digest(h, value[k])
    elif isinstance(value, (list, tuple)):
        for v in value:
            _digest(h, v)
    elif isinstance(value, torch.Tensor):
        h.update(str(value.dtype).encode())
        h.update(value.detach().cpu().contiguous().numpy().tobytes())
    elif isinstance(value, np.ndarray):
        h.update(value.tobytes())
    else:
        h.update(repr(value).encode())


def _row(result: dict, reported: tuple[str, ...]) -> dict:
    from lac_rllib.constrained.metrics import iteration_row

    row = iteration_row(result, reported)
    return {k: v for k, v in row.items() if "time" not in k and not k.endswith("_s")}


def run_hash(algo: str, task: str, seed: int, iterations: int, timesteps: int, sets: dict | None = None) -> str:
    from ray.rllib.core import DEFAULT_MODULE_ID  # noqa: F401  (RLlib loaded before the build)

    from lac_rllib.algorithms.registry import build_config

    torch.set_num_threads(1)
    config = build_config(algo, task, seed, dict(sets or {}), timesteps=timesteps)
    reported = tuple(type(config).REPORTED_KEYS)  # the learner's values (losses) each row carries
    algo_obj = config.build_algo()
    try:
        rows = [_row(algo_obj.train(), reported) for _ in range(iterations)]
        learner = algo_obj.learner_group._learner
        state = {mid: m.state_dict() for mid, m in learner.module.items()}
        optims = {name: opt.state_dict() for name, opt in sorted(learner._named_optimizers.items())}
    finally:
        algo_obj.stop()
    h = hashlib.sha256()
    _digest(h, {"module": state, "optimizers": optims, "rows": json.loads(json.dumps(rows, default=str))})
    return h.hexdigest()[:16]


def main(argv=None) -> None:
    import ray

    from lac_rllib.algorithms.registry import ALGOS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="SafetyPointGoal1-v0")
    parser.add_argument("--iterations", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timesteps", type=int, default=500_000, help="the runs' horizon (lr decays)")
    parser.add_argument("--algos", default=",".join(ALGOS), metavar="A,B,...")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="a field set in every run, e.g. env_backend=stock")
    args = parser.parse_args(argv)
    algos = args.algos.split(",")
    unknown = [a for a in algos if a not in ALGOS]
    if unknown:
        parser.error(f"--algos {','.join(unknown)}: unknown; accepted: {','.join(ALGOS)}")
    from lac_rllib.constrained.fields import parse_sets
    from lac_rllib.constrained.task_config import SafeTaskParams

    shared = {f.name for f in dataclasses.fields(SafeTaskParams)}  # fields every algorithm has
    sets = parse_sets(args.set, shared, what="shared") if args.set else {}
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        for algo in algos:
            start = time.perf_counter()
            digest = run_hash(algo, args.task, args.seed, args.iterations, args.timesteps, sets)
            print(f"{algo:10s} {digest}  ({time.perf_counter() - start:.0f} s)", flush=True)
    finally:
        ray.shutdown()


if __name__ == "__main__":
    sys.exit(main())
