"""``lac-sweep calibrate``: a task's cost range, and a ladder of cost limits proposed inside it.

Users ask how to choose the cost limit of a new env (omnisafe#293, #363). Two short runs bound
the costs that matter: a random policy's episodes, and the algorithm's with its multiplier pinned
at 0 (``nu_fixed=0``: it learns the reward alone, so its cost is what a limit has to pull down).
Their mean episode costs (the task's own convention: summed, or discounted by its
``episode_cost_discount``) are the two ends; the ladder is ``limits`` values from the lower end
up, evenly spaced and short of the upper one (at the upper end the constraint no longer binds),
rounded to two significant figures, with 0 first (one of the ``limits``) where an episode of either run cost 0 (a zero
cost is reachable there; omnisafe#384: a limit of 0 must work, and does here). It is printed and
written as a sweep-file snippet (``cost_limits: [...]``).

Beside it, the fixed-multiplier frontier's ν values (``frontier: {algo: ALGO, nu: [...]}``, for the
regret at each limit): the scale at which the trade-off happens is ν* = (R_free − R_random) /
C_free, the multiplier at which the unconstrained policy's whole cost weighs as much as its whole
gain over a random policy (the Lagrangian adds −ν × cost to the return); the proposal is 0 and a
geometric grid from ν*/16 to 2ν*, so that the costs of the fixed-ν policies spread across the
ladder and R*(b) can differ between rungs. It is a proposal from two short runs: the ladder's
report says where two rungs still share one frontier point (sweeps/reports/ladder.py).

    lac-sweep calibrate --task lac/PointHazard-v0 [--algo ppo_lag] [--timesteps 20000]
    lac-sweep calibrate --config my_sweep.yaml          # its tasks, a user's env included
    lac-sweep calibrate --task SafetyPointGoal2-v0 --constraint vases   # one of several constraints

With ``--constraint NAME`` both runs' costs are that constraint's (docs/constraints.md): the
unconstrained run holds every constraint of the task apart with every ν at 0, and the snippet is a
ladder along that constraint (``ladder_constraint``; the sweep file's ``constraints`` gives the
others' limits).

Every check runs before Ray starts; a user's env is announced before it is built.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

PROG = "lac-sweep calibrate"
#: What the unconstrained run is scored on: the mean episode cost of its last fifth of iterations.
TAIL = 0.2


@dataclasses.dataclass
class Calibration:
    """One task's two runs and the ladder proposed between them."""

    task: str
    algo: str
    random_costs: list[float]  # each random episode's cost
    free_costs: list[float]  # the unconstrained run's mean episode cost per iteration, its tail
    zero_seen: bool  # an episode of either run cost 0
    ladder: list[float]
    random_returns: list[float] = dataclasses.field(default_factory=list)  # each random episode's return
    free_returns: list[float] = dataclasses.field(default_factory=list)  # the unconstrained run's, its tail
    frontier: list[float] = dataclasses.field(default_factory=list)  # the proposed fixed ν values
    constraint: str | None = None  # the one constraint of several whose costs these are

    @property
    def random_cost(self) -> float:
        return float(np.mean(self.random_costs))

    @property
    def free_cost(self) -> float:
        return float(np.mean(self.free_costs))


def round2(x: float) -> float:
    """``x`` to two significant figures (0 stays 0)."""
    return 0.0 if x == 0 else float(f"{x:.2g}")


def propose_ladder(low: float, high: float, limits: int, zero: bool) -> list[float]:
    """``limits`` increasing limits: 0 first where ``zero``, the others from ``low`` towards ``high``
    (evenly spaced, ``high`` itself left out: the constraint binds below it), rounded and distinct;
    the ends may come in either order."""
    low, high = sorted((max(0.0, low), max(0.0, high)))
    spaced = limits - 1 if zero else limits
    values = [round2(low + (high - low) * k / spaced) for k in range(spaced)]
    return sorted(set(([0.0] if zero else []) + values))


def propose_frontier(gain: float, cost: float, points: int = 6) -> list[float]:
    """0 and ``points`` fixed ν values, a geometric grid from ν*/16 to 2ν* with ν* = ``gain`` / ``cost``
    (the module docstring), rounded to two significant figures; [0] alone where the unconstrained run
    paid no cost or gained nothing (no ν trades anything there)."""
    if not (math.isfinite(gain) and math.isfinite(cost)) or cost <= 0 or gain <= 0:
        return [0.0]
    scale = gain / cost
    return sorted({0.0, *(round2(scale * 2.0 ** k) for k in np.linspace(-4, 1, points))})


def random_episode_costs(spec, episodes: int, seed: int, constraint: str | None = None
                         ) -> tuple[list[float], bool, list[float]]:
    """Each of ``episodes`` random-action episodes' cost, in the task's convention (seeded: episode
    i is reset with seed + i), whether any of them cost 0, and each episode's return; the cost is
    ``constraint``'s where one is named."""
    own = next(c for c in spec.constraints if c.name == constraint) if constraint else None
    env = spec.make()
    env.action_space.seed(seed)
    costs, returns = [], []
    try:
        for i in range(episodes):
            env.reset(seed=seed + i)
            total, ret, discount, done = 0.0, 0.0, 1.0, False
            while not done:
                _, reward, terminated, truncated, info = env.step(env.action_space.sample())
                total += discount * (own.step_cost(info) if own else float(info.get("cost", 0.0)))
                ret += float(reward)
                discount *= spec.episode_cost_discount
                done = terminated or truncated
            costs.append(total)
            returns.append(ret)
    finally:
        env.close()
    return costs, any(c == 0 for c in costs), returns


def unconstrained_costs(algo: str, task: str, timesteps: int, seed: int, constraint: str | None = None
                        ) -> tuple[list[float], bool, list[float]]:
    """The mean episode cost of each of the last TAIL of iterations of ``algo`` on ``task`` with ν
    pinned at 0 (``nu_fixed``) at its quick sizes, whether an iteration's mean cost was 0, and those
    iterations' mean episode returns; ``constraint``'s cost where one is named (every constraint of
    the task then held apart, each ν at 0)."""
    import ray

    from lac_rllib.algorithms import registry
    from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN, iteration_row, per_constraint
    from lac_rllib.tasks import get_task

    sets = {**registry.budget_fields(algo, "quick", get_task(task).preset), "nu_fixed": 0.0}
    names = [c.name for c in get_task(task).constraints]
    if constraint:  # every constraint apart (their limits change nothing with ν at 0): each one's cost
        sets["constraints"] = dict.fromkeys(names, 0.0)
    key = per_constraint(EPISODE_COST, constraint) if constraint and len(names) > 1 else EPISODE_COST
    config = registry.build_config(algo, task, seed, sets, timesteps=timesteps)
    # One process: the env runner samples in the driver, where a user's env module is importable
    # (its folder travels in the task's kwargs: lac_rllib/tasks/user.py). A caller's Ray is used as it is.
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    rows = []
    try:
        algo_obj = config.build_algo()
        try:
            while not rows or rows[-1][ENV_STEPS] < timesteps:
                rows.append(iteration_row(algo_obj.train()))
        finally:
            algo_obj.stop()
    finally:
        if started:
            ray.shutdown()
    rows = [r for r in rows if math.isfinite(r.get(key, math.nan))]
    tail = rows[-max(1, math.ceil(TAIL * len(rows))):]
    costs = [r[key] for r in tail]
    return costs, any(c == 0 for c in costs), [r[EPISODE_RETURN] for r in tail if math.isfinite(r[EPISODE_RETURN])]


def calibrate(task: str, algo: str, timesteps: int, episodes: int, limits: int, seed: int,
              constraint: str | None = None) -> Calibration:
    """Both runs on ``task`` and the ladder between them (the module docstring), on ``constraint``'s
    cost where one is named."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    rand, rand_zero, rand_ret = random_episode_costs(spec, episodes, seed, constraint)
    free, free_zero, free_ret = unconstrained_costs(algo, task, timesteps, seed, constraint)
    zero = rand_zero or free_zero
    ladder = propose_ladder(float(np.mean(rand)), float(np.mean(free)), limits, zero)
    gain = float(np.mean(free_ret)) - float(np.mean(rand_ret)) if free_ret and rand_ret else math.nan
    return Calibration(task, algo, rand, free, zero, ladder, rand_ret, free_ret,
                       propose_frontier(gain, float(np.mean(free))), constraint)


def snippet(c: Calibration, timesteps: int) -> str:
    """The sweep-file snippet of a calibration: its ladder and, as comments, where it came from."""
    along = (f"# along {c.constraint}: its cost alone; constraints: {{...}} gives the others' limits\n"
             f"ladder_constraint: {c.constraint}\n" if c.constraint else "")
    return (f"# lac-sweep calibrate: {c.task}, a random policy's episodes cost {c.random_cost:.3g} on average, "
            f"{c.algo} with nu pinned at 0 ({timesteps:,} env steps) {c.free_cost:.3g}"
            f"{'; an episode cost 0, so the ladder starts at 0' if c.zero_seen else ''}\n"
            f"{along}cost_limits: [{', '.join(f'{b:g}' for b in c.ladder)}]\n"
            + (f"# the frontier: nu* = (return {np.mean(c.free_returns):.3g} - random {np.mean(c.random_returns):.3g})"
               f" / cost {c.free_cost:.3g}; 0 and nu*/16 .. 2 nu*\n"
               f"frontier: {{algo: {c.algo}, nu: [{', '.join(f'{v:g}' for v in c.frontier)}]}}\n"
               if len(c.frontier) > 1 else ""))


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--task", help="a registered task id (lac-sweep --list-tasks names them)")
    src.add_argument("--config", metavar="FILE.yaml", help="a sweep file: calibrate each of its tasks")
    p.add_argument("--algo", default=None, help="the algorithm run with nu pinned at 0 (default: the first the "
                                                "sweep file names, else LAC); one with a Lagrange multiplier")
    p.add_argument("--timesteps", type=int, default=20_000, help="its env steps (default 20,000)")
    p.add_argument("--episodes", type=int, default=20, help="the random policy's episodes (default 20)")
    p.add_argument("--limits", type=int, default=4, help="limits in the ladder, 0 included where proposed (default 4)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--constraint", default=None, metavar="NAME",
                   help="one of the task's constraints (docs/constraints.md): calibrate a ladder along its cost alone")
    p.add_argument("--out", default=None, metavar="FILE.yaml",
                   help="where the snippet goes (default: calibrate-TASK.yaml here, one per task)")
    return p


def check(args, algo: str) -> None:
    """Every argument, before anything runs."""
    from lac_rllib.algorithms import registry

    for name, low in (("timesteps", 1), ("episodes", 1), ("limits", 2)):
        if getattr(args, name) < low:
            raise ValueError(f"--{name} {getattr(args, name)} is invalid; accepted: an integer >= {low}")
    registry.check_algo(algo, (str(Path.cwd()),))
    if not registry.has_multiplier(algo):
        raise ValueError(f"--algo {algo} has no Lagrange multiplier to pin at 0; accepted: "
                         f"{registry.with_multiplier_text()}")


def check_constraint(name: str | None, ids: list[str]) -> None:
    """``--constraint``: one every task declares (each task's accepted ones named where it lacks it)."""
    from lac_rllib.tasks import get_task

    for task in ids if name else ():
        names = [c.name for c in get_task(task).constraints]
        if name not in names:
            raise ValueError(f"--constraint {name}: {task} has no constraint {name!r}; accepted: "
                             f"{', '.join(names) or 'none: it declares no constraints'}")


def tasks_of(args) -> tuple[list[str], str | None]:
    """The task ids to calibrate (a sweep file's users' envs built, stepped and registered) and the
    algorithm the sweep file names first (None without one)."""
    if args.task:
        from lac_rllib.tasks import get_task

        get_task(args.task)  # unknown id -> ValueError naming the closest known ones
        return [args.task], None
    from sweeps import sweep_file
    from sweeps.plan import resolve_tasks

    path = Path(args.config)
    sweep, origin = sweep_file.load_with_origin(path)
    ids, _ = resolve_tasks(sweep, (str(path.resolve().parent),), origin)
    algos = [a for a in (sweep.algo or ()) if isinstance(a, str)]
    return ids, (algos[0] if algos else None)


def main(argv: list[str] | None = None) -> int:
    from lac_rllib.algorithms import registry

    p = parser()
    args = p.parse_args(argv)
    try:
        ids, first = tasks_of(args)
        algo = args.algo or first or registry.DEFAULT_ALGO
        check(args, algo)
        check_constraint(args.constraint, ids)
    except (ValueError, OSError) as e:  # a SweepFileError is a ValueError
        p.exit(2, f"{PROG}: error: {e}\n")
    for task in ids:
        c = calibrate(task, algo, args.timesteps, args.episodes, args.limits, args.seed, args.constraint)
        text = snippet(c, args.timesteps)
        out = Path(args.out or f"calibrate-{task.replace('/', '_')}.yaml")
        if args.out and len(ids) > 1:
            out = out.with_name(f"{out.stem}-{task.replace('/', '_')}{out.suffix}")
        out.write_text(text, encoding="utf-8")
        print(f"{task}: random policy {c.random_cost:.3g} per episode ({len(c.random_costs)} episodes), {algo} "
              f"with nu = 0 {c.free_cost:.3g} (its last {len(c.free_costs)} iterations)\n{text}-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
