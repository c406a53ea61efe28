"""The batched navigation env's speed beside the stock env's and the physics floor, one core.

For each task and N (envs in one vector env): steps/s of
- **stock**: gymnasium's ``SyncVectorEnv`` of N stock envs (Safety-Gymnasium 1.0.0 as this project
  runs it: the compat shim and light resets; ``env_backend: stock``);
- **batched**: lac_rllib/tasks/batched_navigation.py (``env_backend: batched``, the default);
- **physics**: the same N simulations' MuJoCo calls alone (per env step: the control written,
  ``mj_step`` with the frame skip, one ``mj_forward``): what no task layer can beat.
Same seeds, same random actions (episodes end and reset inside the timing, as in training); the
three are timed in turn, ``--repeats`` times, and the best of each is kept (the least disturbed).
The goal of issue 57: batched ≥ 4× stock at N = 10 and within 2× of the physics floor.

    taskset -c 0 python benchmarks/batched_env.py                       # PointGoal1, N = 1, 10, 32
    taskset -c 0 python benchmarks/batched_env.py --tasks SafetyCarButton2-v0 --envs 10
"""

from __future__ import annotations

import argparse
import subprocess
import time

import mujoco
import numpy as np


def _actions(env, steps: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, size=(steps, *env.action_space.shape)).astype(np.float32)


def _time_env(env, actions, seed: int) -> float:
    env.reset(seed=seed)
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    return time.perf_counter() - start


def _time_physics(batched, actions) -> float:
    """The batched env's own models and data, stepped as its step steps them, nothing else."""
    sims = [s for s in batched._sims]
    frames = batched._task.sim_conf.frameskip_binom_n
    step, forward = mujoco.mj_step, mujoco.mj_forward
    start = time.perf_counter()
    for a in actions:
        for sim, x in zip(sims, a):
            sim.ctrl[:] = x
            step(sim.model, sim.data, frames)
            forward(sim.model, sim.data)
    return time.perf_counter() - start


def bench(task: str, n: int, steps: int, repeats: int, seed: int = 0) -> dict:
    from gymnasium.vector import SyncVectorEnv

    from lac_rllib.tasks.safety_gym import make_batched, make_env

    stock = SyncVectorEnv([lambda: make_env({"env_id": task}) for _ in range(n)])
    batched = make_batched(task, n)
    actions = _actions(stock, max(1, steps // n), seed)
    best = {"stock": np.inf, "batched": np.inf, "physics": np.inf}
    for _ in range(repeats):
        best["stock"] = min(best["stock"], _time_env(stock, actions, seed))
        best["batched"] = min(best["batched"], _time_env(batched, actions, seed))
        best["physics"] = min(best["physics"], _time_physics(batched, actions))
    stock.close()
    batched.close()
    env_steps = len(actions) * n
    rate = {k: env_steps / v for k, v in best.items()}
    return {"task": task, "n": n, **rate, "speedup": rate["batched"] / rate["stock"],
            "over_floor": rate["physics"] / rate["batched"]}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=["SafetyPointGoal1-v0"])
    p.add_argument("--envs", nargs="+", type=int, default=[1, 10, 32])
    p.add_argument("--steps", type=int, default=6_000, help="env steps per timing")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    cpu = subprocess.run(["sh", "-c", "lscpu | grep 'Model name'"], capture_output=True, text=True).stdout.split(":")
    print(f"CPU: {cpu[-1].strip() if len(cpu) > 1 else 'unknown'}; best of {args.repeats}, {args.steps:,} env steps "
          "each\n")
    print("| task | N | stock steps/s | batched steps/s | physics steps/s | batched / stock | physics / batched |")
    print("|---|---|---|---|---|---|---|")
    for task in args.tasks:
        for n in args.envs:
            r = bench(task, n, args.steps, args.repeats)
            print(f"| {task} | {n} | {r['stock']:,.0f} | {r['batched']:,.0f} | {r['physics']:,.0f} | "
                  f"{r['speedup']:.2f}× | {r['over_floor']:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
