"""One gradient step of each algorithm: RLlib's NaN/inf guard against ours, same run.

    python benchmarks/update_step.py [--task SafetyPointGoal1-v0] [--steps 300] [--repeats 3]

The guard: RLlib's per-tensor tests (``torch_skip_nan_gradients=False``; ours still runs first,
one cheap test more) against ours alone (lac_rllib/constrained/gradients.py), the same update bit
for bit (tests/constrained/test_gradients.py). For each algorithm at the task's preset, two
algorithms are built with the same seed, their data made the same way, and their updates timed
interleaved:
- lac, sac_lag: ms per gradient step of ``update_from_replay`` over ``--steps`` 256-row minibatches
  of the replay buffer, after 2,000 env steps of random actions (LAC: a tenth of the steps, its
  chain makes each ~0.3 s);
- ppo_lag: ms per gradient step of one iteration's update (40 epochs of 64-row minibatches, the
  KL early stop off so that both make every step), on 2,000 env steps per iteration.
Prints the medians and the ratio; one torch thread, one CPU.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time


def _build(algo: str, task: str, defaults: bool):
    """The algorithm as we configure it, or (``defaults``) with RLlib's per-tensor NaN tests."""
    from lac_rllib.algorithms.registry import build_config

    sets = {"lac": {"random_iterations": 1, "env_steps_per_iteration": 2000},
            "sac_lag": {"random_env_steps": 2000, "env_steps_per_iteration": 2000},
            # No KL early stop: every epoch makes all its steps, whatever the data.
            "ppo_lag": {"train_batch_size_per_learner": 2000, "target_kl": None}}[algo]
    config = build_config(algo, task, 0, sets, timesteps=10**7)
    config.torch_skip_nan_gradients = not defaults
    return config.build_algo()


def _timed_update(algo_name: str, algo, steps: int) -> float:
    """Seconds per gradient step of one update call (its gradient steps counted: PPO-Lag's KL
    early stop makes fewer than its epochs say)."""
    learner = algo.learner_group._learner  # local learner (num_learners=0)
    counted, apply = [0], learner.apply_gradients

    def count(*args, **kwargs):
        counted[0] += 1
        return apply(*args, **kwargs)

    learner.apply_gradients, seconds = count, []
    update = algo.learner_group.update

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        out = update(*args, **kwargs)
        seconds.append(time.perf_counter() - t0)
        return out

    algo.learner_group.update = timed
    try:
        if algo_name == "ppo_lag":
            algo.train()
        else:
            algo.update_from_replay(minibatch_size=256, num_minibatches=steps, timesteps={})
    finally:
        learner.apply_gradients, algo.learner_group.update = apply, update
    return sum(seconds) / max(counted[0], 1)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="SafetyPointGoal1-v0")
    parser.add_argument("--algos", default="sac_lag,ppo_lag,lac")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    from lac_rllib.algorithms.registry import check_algo
    from lac_rllib.tasks import get_task

    try:  # bad input, before Ray starts
        get_task(args.task)
        for name in args.algos.split(","):
            check_algo(name)
        if args.steps < 10 or args.repeats < 1:
            raise ValueError(f"--steps {args.steps} / --repeats {args.repeats}; "
                             "accepted: --steps >= 10, --repeats >= 1")
    except ValueError as e:
        parser.exit(2, f"update_step: error: {e}\n")
    import ray
    import torch

    torch.set_num_threads(1)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    lines = ["| algorithm | ms per step, RLlib's guard | ms per step, ours | ratio |",
             "|---|---:|---:|---:|"]
    for name in args.algos.split(","):
        algos = {defaults: _build(name, args.task, defaults) for defaults in (True, False)}
        try:
            if name != "ppo_lag":
                for a in algos.values():
                    a.train()  # fills the buffer (random actions)
                    _timed_update(name, a, 10)  # warm-up: a compile (LAC's chain), first allocations
            times = {defaults: [] for defaults in algos}
            for _ in range(args.repeats):
                for defaults, a in algos.items():
                    times[defaults].append(_timed_update(name, a, args.steps // 10 if name == "lac" else args.steps))
        finally:
            for a in algos.values():
                a.stop()
        old, new = (1e3 * statistics.median(times[d]) for d in (True, False))
        lines.append(f"| {name} | {old:.2f} | {new:.2f} | {old / new:.2f}x |")
        print(lines[-1], flush=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
