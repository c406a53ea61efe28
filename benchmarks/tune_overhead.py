"""Tune's overhead per trial: the same trials through the sweep service (Tune + MLflow, one at a
time) and back to back in one process (``lac_rllib.train.train``), measured in the same run.

    python benchmarks/tune_overhead.py [--space smoke] [--budget smoke] [--trials 4]

Figures only, no asserts. Overhead per trial = (sweep wall time − direct wall time) / trials; it
includes actor start-up, Tune's checkpoint every iteration and the MLflow logging.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--space", default="smoke")
    p.add_argument("--budget", default="smoke")
    p.add_argument("--task", default=None)
    p.add_argument("--trials", type=int, default=4)
    a = p.parse_args()

    import ray

    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.train import train
    from sweeps import run as cli
    from sweeps.sweep import run_sweep

    tmp = Path(tempfile.mkdtemp(prefix="tune_overhead_"))
    args = cli.parse_args(["--space", a.space, "--budget", a.budget, "--seeds", "1", "--max-concurrent", "1",
                           "--tracking-uri", f"sqlite:///{tmp / 'mlflow.db'}", "--storage", str(tmp / "ray_results"),
                           "--experiment", "overhead", *(["--task", a.task] if a.task else [])])
    plan, = cli.make_plan(args)
    plan = dataclasses.replace(plan, trials=plan.trials[: a.trials], n_trials=min(a.trials, plan.n_trials),
                               concurrency=1)
    ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False, logging_level="ERROR")

    start = time.perf_counter()
    for t in plan.trials:  # with the LAC fields the plan resolved for it, as its sweep trial runs
        config = LACConfig.build(t.task, t.seed, t.params, timesteps=plan.timesteps)
        train(config, plan.timesteps, str(tmp / "direct" / t.label()), log=lambda *x, **k: None)
    direct = time.perf_counter() - start

    start = time.perf_counter()
    run_sweep(plan, args, Path(plan.storage) / plan.name, "benchmark")
    tuned = time.perf_counter() - start

    n = len(plan.trials)
    print(f"\n{n} trials of {a.space}/{a.budget} ({plan.timesteps} env steps each), one at a time:")
    print(f"  back to back in one process: {direct:7.1f} s  ({direct / n:.1f} s/trial)")
    print(f"  through Tune + MLflow:       {tuned:7.1f} s  ({tuned / n:.1f} s/trial)")
    print(f"  Tune's overhead per trial:   {(tuned - direct) / n:7.1f} s  (ratio {tuned / direct:.2f}x)")


if __name__ == "__main__":
    main()
