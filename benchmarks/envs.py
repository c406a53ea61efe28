"""Environment speed.

Part 1 (here): raw steps/s per task: random actions, one process, reset on episode end (reset
time included, as it is in training). Part 2, through LAC's sampling path, is added later.

    python benchmarks/envs.py                     # every registered task, 3000 steps each
    python benchmarks/envs.py --steps 5000 SafetyPointGoal1-v0 focops/AntVelocity-v0
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lac_rllib.tasks import get_task, known_tasks
from lac_rllib.tasks.versions import runtime_versions


def bench_raw(task_ids: list[str] | None = None, steps: int = 3000, seed: int = 0) -> list[dict]:
    """Steps/s of each task's env with uniform random actions; prints a table, returns rows.

    Env construction and the first reset are not timed; later resets (on termination or
    truncation) are. Each row: task, steps, episodes (completed), seconds, steps_per_s,
    mean_episode_len (completed episodes; None if none completed), cost_per_step.
    """
    rows = []
    for task_id in task_ids or known_tasks():
        env = get_task(task_id).make()
        env.action_space.seed(seed)
        env.reset(seed=seed)
        actions = [env.action_space.sample() for _ in range(steps)]
        episodes, ep_len, lens, cost = 0, 0, [], 0.0
        t0 = time.perf_counter()
        for action in actions:
            _, _, term, trunc, info = env.step(action)
            cost += info["cost"]
            ep_len += 1
            if term or trunc:
                episodes += 1
                lens.append(ep_len)
                ep_len = 0
                env.reset()
        seconds = time.perf_counter() - t0
        env.close()
        rows.append(
            {
                "task": task_id,
                "steps": steps,
                "episodes": episodes,
                "seconds": seconds,
                "steps_per_s": steps / seconds,
                "mean_episode_len": float(np.mean(lens)) if lens else None,
                "cost_per_step": cost / steps,
            }
        )
    _print_table(rows)
    return rows


def _print_table(rows: list[dict]) -> None:
    header = f"{'task':<30} {'steps/s':>9} {'steps':>6} {'episodes':>8} {'mean ep len':>11} {'cost/step':>9}"
    print(header)
    print("-" * len(header))
    for r in rows:
        mean_len = "-" if r["mean_episode_len"] is None else f"{r['mean_episode_len']:.1f}"
        print(
            f"{r['task']:<30} {r['steps_per_s']:>9,.0f} {r['steps']:>6} {r['episodes']:>8} "
            f"{mean_len:>11} {r['cost_per_step']:>9.3f}"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="*", help="task ids (default: all registered)")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(runtime_versions())
    bench_raw(args.tasks or None, args.steps, args.seed)


if __name__ == "__main__":
    main()
