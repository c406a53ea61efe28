"""The batched navigation env against stock Safety-Gymnasium over long streams, every batched id.

For each id: N stock envs and the batched env, the same seed and actions (steering to the goal
most of the time, noise otherwise: lac_rllib/tasks/navigation_equality.py), compared after every
step: every observation, reward, terminated, truncated, each ``cost_*`` key, ``cost_sum`` and
``cost``, ``goal_met``, and every env's layout (each reset's, each resampled goal's). Default: 4
envs × 25,250 steps: ≥ 100,000 env steps and 100 episode ends per id at the tasks' own 1,000-step
episodes. Prints one line per id and writes them to ``--out`` (the committed record:
docs/speed/batched-equality.md); exits 1 if any id differed.

    python benchmarks/batched_equality.py --out docs/speed/batched-equality.md
    python benchmarks/batched_equality.py --ids SafetyPointGoal1-v0 --steps 2000   # a quick look
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from lac_rllib.tasks.navigation_equality import compare
from lac_rllib.tasks.safety_gym import BATCHED_FAMILIES, BATCHED_ROBOTS
from lac_rllib.tasks.versions import runtime_versions

IDS = [f"Safety{r}{f}{level}-v0" for f in BATCHED_FAMILIES for r in BATCHED_ROBOTS for level in (0, 1, 2)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ids", nargs="+", default=IDS)
    p.add_argument("--envs", type=int, default=4)
    p.add_argument("--steps", type=int, default=25_250, help="vector steps per id (each reset takes one)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="also write the table here (Markdown)")
    args = p.parse_args(argv)
    v = runtime_versions()
    cpu = subprocess.run(["sh", "-c", "lscpu | grep 'Model name'"], capture_output=True, text=True).stdout
    lines = [f"Seed {args.seed}, {args.envs} envs × {args.steps:,} steps per id; safety_gymnasium "
             f"{v.get('safety_gymnasium')}, mujoco {v.get('mujoco')}, gymnasium {v.get('gymnasium')}, numpy "
             f"{v.get('numpy')}; {cpu.split(':')[-1].strip()}.", "",
             "| id | env steps | episode ends | goals met | steps with cost | result | minutes |",
             "|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    failed = 0
    for env_id in args.ids:
        start = time.perf_counter()
        c = compare(env_id, args.envs, args.steps, args.seed)
        result = "identical" if c.identical else f"{len(c.mismatches)} mismatches, first at step {c.mismatches[0]}"
        failed += not c.identical
        lines.append(f"| {env_id} | {c.steps:,} | {c.episodes} | {c.goals} | {c.cost_steps:,} | {result} | "
                     f"{(time.perf_counter() - start) / 60:.1f} |")
        print(lines[-1], flush=True)
        if args.out:
            Path(args.out).write_text("\n".join(lines) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
