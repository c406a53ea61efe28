"""Environment speed: raw env steps/s, and steps/s through LAC's sampling path.

Part 1, ``bench_raw``: raw steps/s per task: random actions, one process, reset on episode end
(reset time included, as it is in training); navigation tasks also with Safety-Gymnasium's
stock resets (env_config ``light_resets=False``) for comparison.

Part 2, ``bench_sampling``: the same raw measurement, then steps/s of an LAC algorithm's local
env runner (``num_env_runners=0``, one process): RLlib's vector env and episodes, the env-to-module
connectors (MeanStdFilter on, as by default), the generator actor of the task's preset acting
(exploration sampling), the episode-cost callback, the module-to-env connectors (action
clipping). No learning. Measured with one env per runner (the baseline) and with the preset's
``num_envs_per_env_runner`` (8 for Safety-Gymnasium tasks), all in the same run, with the
ratios to raw.

    python benchmarks/envs.py                       # raw + sampling, every task but CostProbe
    python benchmarks/envs.py --steps 5000 --tasks SafetyPointGoal1-v0 focops/AntVelocity-v0
    python benchmarks/envs.py --raw-only            # part 1 only (no Ray)
    python benchmarks/envs.py --step-costs          # navigation tasks' step costs (the plan's)

Part 3, ``bench_step_costs``: each Safety-Gymnasium navigation task's raw step time over
``SafetyPointGoal1-v0``'s, the reference timed just before and after each task so that a change of
the machine's load falls on both; printed in the layout of ``NAV_STEP_COST``
(lac_rllib/tasks/safety_gym.py), which the sweep plan reads through ``TaskSpec.step_cost``.
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
    for task_id in task_ids or sampling_tasks():
        rows.append(_raw_row(task_id, steps, seed))
        if task_id.startswith("Safety") and "Velocity" not in task_id:  # navigation: stock resets too
            stock = _raw_row(task_id, steps, seed, {"light_resets": False})
            rows.append({**stock, "task": task_id + " (stock resets)"})
    _print_table(rows)
    return rows


def _raw_row(task_id: str, steps: int, seed: int, env_config: dict | None = None) -> dict:
    env = get_task(task_id).make(env_config)
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
    return {
        "task": task_id,
        "steps": steps,
        "episodes": episodes,
        "seconds": seconds,
        "steps_per_s": steps / seconds,
        "mean_episode_len": float(np.mean(lens)) if lens else None,
        "cost_per_step": cost / steps,
    }


#: The Safety-Gymnasium ids the paper's tasks and the velocity v1 family stand for (docs/tasks.md lists
#: all 71 registered; ``--tasks`` names any of them).
SAFETY_DEFAULT = ("SafetyPointGoal1-v0", "SafetyCarGoal1-v0", "SafetyPointButton1-v0", "SafetyCarButton1-v0",
                  "SafetyAntVelocity-v1", "SafetySwimmerVelocity-v1", "SafetyHumanoidVelocity-v1")


def sampling_tasks() -> list[str]:
    """The built-in tasks (lac/, focops/) and the paper's Safety-Gymnasium ids, without the
    diagnostic ``lac/CostProbe-v0``."""
    return [t for t in known_tasks() if t != "lac/CostProbe-v0" and (not t.startswith("Safety") or t in SAFETY_DEFAULT)]


def bench_sampling(task_ids: list[str] | None = None, steps: int = 3000, seed: int = 0,
                   warmup: int = 50) -> list[dict]:
    """Raw steps/s and steps/s through LAC's sampling path, per task, in one run.

    Sampling path: ``LACConfig().task(id)`` (the task's preset: default network sizes,
    observation filter on), ``num_env_runners=0``, ``algo.env_runner.sample(num_timesteps=steps,
    explore=True, random_actions=False)`` (the generator acts), no learning. Algorithm build,
    the first reset and ``warmup`` steps (connector/module warm-up) are not timed; later resets
    are, as in :func:`bench_raw`. Torch runs with 1 thread. Starts Ray (1 CPU) if needed.
    Each row: task, steps, envs (the preset's envs per runner), raw_steps_per_s,
    one_env_steps_per_s, sampling_steps_per_s (preset's envs), ratio_one_env and ratio (each
    over raw), sampling_episodes (completed in the timed sample). Prints a table, returns the rows.
    """
    import ray
    import torch

    from lac_rllib.algorithms.lac.config import LACConfig

    torch.set_num_threads(1)
    if not ray.is_initialized():
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    rows = []
    for task_id in task_ids or sampling_tasks():
        raw = _raw_row(task_id, steps, seed)
        preset_envs = LACConfig().task(task_id).num_envs_per_env_runner
        one, _ = _sampling_steps_per_s(task_id, steps, seed, warmup, num_envs=1)
        many, episodes = (one, None) if preset_envs == 1 else _sampling_steps_per_s(
            task_id, steps, seed, warmup, num_envs=preset_envs)
        row = {
            "task": task_id,
            "steps": steps,
            "envs": preset_envs,
            "raw_steps_per_s": raw["steps_per_s"],
            "one_env_steps_per_s": one,
            "sampling_steps_per_s": many,
        }
        row["ratio_one_env"] = one / raw["steps_per_s"]
        row["ratio"] = many / raw["steps_per_s"]
        rows.append(row)
        print(f"  {task_id}: raw {raw['steps_per_s']:,.0f} steps/s, sampling {one:,.0f} (1 env) / "
              f"{many:,.0f} ({preset_envs} envs) steps/s", flush=True)
    _print_sampling_table(rows)
    return rows


def _sampling_steps_per_s(task_id: str, steps: int, seed: int, warmup: int, num_envs: int):
    from lac_rllib.algorithms.lac.config import LACConfig

    config = (LACConfig().task(task_id).training(total_env_steps=steps, num_envs_per_env_runner=num_envs)
              .debugging(seed=seed).env_runners(num_env_runners=0))
    algo = config.build_algo()
    try:
        runner = algo.env_runner
        runner.sample(num_timesteps=warmup, explore=True, random_actions=False)
        t0 = time.perf_counter()
        episodes = runner.sample(num_timesteps=steps, explore=True, random_actions=False)
        seconds = time.perf_counter() - t0
    finally:
        algo.stop()
    sampled = sum(len(e) for e in episodes)
    # A vector env stops at the first full round of its envs past ``steps``.
    assert steps <= sampled < steps + num_envs, f"{task_id}: sampled {sampled} steps, expected {steps}"
    return sampled / seconds, episodes


def bench_step_costs(steps: int = 1000, seed: int = 0, reference: str = "SafetyPointGoal1-v0") -> dict:
    """{(task, robot): a raw step's time over the reference's} for every navigation task
    (module docstring, part 3); prints the table in ``NAV_STEP_COST``'s layout."""
    from lac_rllib.tasks.safety_gym import NAV_OBS_DIMS, NAV_ROBOTS, nav_id

    ref = get_task(reference).make()
    ref.reset(seed=seed)
    _seconds_of(ref, steps // 5, seed)
    costs = {}
    for task in NAV_OBS_DIMS:
        for robot in NAV_ROBOTS:
            env = get_task(nav_id(robot, task)).make()
            env.reset(seed=seed)
            _seconds_of(env, steps // 5, seed)  # warm (a fresh env's first steps run slower)
            before = _seconds_of(ref, steps, seed)
            seconds = _seconds_of(env, steps, seed)
            after = _seconds_of(ref, steps, seed)
            env.close()
            costs[task, robot] = seconds / (0.5 * (before + after))
        cells = ", ".join(f"{c:.2g}" if c < 10 else f"{c:.0f}" for c in (costs[task, r] for r in NAV_ROBOTS))
        print(f'    "{task}": ({cells}),', flush=True)
    ref.close()
    return costs


def _seconds_of(env, steps: int, seed: int) -> float:
    """Seconds of ``steps`` random-action steps of ``env`` (resets on episode end included)."""
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    t0 = time.perf_counter()
    for action in actions:
        _, _, term, trunc, _ = env.step(action)
        if term or trunc:
            env.reset()
    return time.perf_counter() - t0


def _print_sampling_table(rows: list[dict]) -> None:
    header = (f"{'task':<30} {'raw steps/s':>11} {'1 env':>8} {'ratio':>6} {'envs':>4} {'N envs':>8} "
              f"{'ratio':>6} {'steps':>6}")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['task']:<30} {r['raw_steps_per_s']:>11,.0f} {r['one_env_steps_per_s']:>8,.0f} "
              f"{r['ratio_one_env']:>6.2f} {r['envs']:>4} {r['sampling_steps_per_s']:>8,.0f} {r['ratio']:>6.2f} "
              f"{r['steps']:>6}")


def _print_table(rows: list[dict]) -> None:
    header = f"{'task':<45} {'steps/s':>9} {'steps':>6} {'episodes':>8} {'mean ep len':>11} {'cost/step':>9}"
    print(header)
    print("-" * len(header))
    for r in rows:
        mean_len = "-" if r["mean_episode_len"] is None else f"{r['mean_episode_len']:.1f}"
        print(
            f"{r['task']:<45} {r['steps_per_s']:>9,.0f} {r['steps']:>6} {r['episodes']:>8} "
            f"{mean_len:>11} {r['cost_per_step']:>9.3f}"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("positional_tasks", nargs="*", metavar="TASK", help="task ids (same as --tasks)")
    parser.add_argument("--tasks", nargs="+", default=[], metavar="TASK",
                        help="task ids (default: every registered task but lac/CostProbe-v0; "
                             "with --raw-only, every registered task)")
    parser.add_argument("--steps", type=int, default=3000, help="timed steps per task and measurement")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--raw-only", action="store_true", help="only the raw env table (part 1)")
    parser.add_argument("--step-costs", action="store_true",
                        help="only the navigation tasks' step costs over SafetyPointGoal1-v0's (part 3)")
    args = parser.parse_args(argv)
    tasks = [*args.positional_tasks, *args.tasks] or None
    for task_id in tasks or []:
        get_task(task_id)  # unknown id -> ValueError listing the known ones, before any work
    print(runtime_versions())
    if args.step_costs:
        bench_step_costs(args.steps, args.seed)
    elif args.raw_only:
        bench_raw(tasks, args.steps, args.seed)
    else:
        bench_sampling(tasks, args.steps, args.seed)


if __name__ == "__main__":
    main()
