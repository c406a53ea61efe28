"""One gradient step of each baseline, four ways, same run: RLlib's update path, the fused one (the
default), a plain-torch step of the same networks, losses and optimizers, and that step's matmul
floor.

    python benchmarks/update_step.py [--task SafetyPointGoal1-v0] [--algos ppo_lag,sac_lag] [--steps 300] [--repeats 3]
    python benchmarks/update_step.py --against REV [--algos ppo_lag,sac_lag] [--repeats 5]

For each algorithm at the task's preset, two algorithms are built from one seed, ``update_path=
"rllib"`` (RLlib's minibatch iterator, its PPO loss, torch's per-tensor Adam, its clip: the update
as it was before the fused path) and ``"fused"``, their data made the same way and their update
calls timed interleaved, in ms per gradient step of a call:
- ppo_lag: one iteration's update (``--steps`` ×10 env steps per iteration: 3,000 by default,
  ~1,900 steps of 64-row minibatches at OmniSafe's 40 epochs; the KL early stop off, so that both
  make every step);
- sac_lag: one iteration's update of ``--steps`` 256-row steps (one per env step), after 2,000
  random env steps.
- the baselines built on one of those (the first-order ones on PPO-Lag's house: ``registry.house``):
  as their house, at its sizes (``benchmark_fields``: PPO-Lag's (64, 64) networks, 64-row
  minibatches, 40 epochs), so the last column times their step against their house's fused step,
  built beside it and timed in the same interleaved repeats, on the same
  shapes (their maths differs from PPO-Lag's in the policy's loss only). Their RLlib path runs
  their own loss too.
Beside them, :mod:`reference_steps`' plain-torch step on minibatches of the same shapes (its loss
and gradients are the learner's: tests/benchmarks/test_update_step.py) and its time inside matrix
products, for the algorithms it has a step of. Prints medians over ``--repeats`` and the ratios;
one torch thread, one CPU. PPO-Lag's and SAC-Lag's two paths make the same update bit for bit
(tests/algorithms/test_update_path.py).

``--against REV`` times instead the default step of the code at git revision ``REV`` (a commit, a
tag: say, the one an issue was filed against) beside today's, same run (:mod:`revision`): ``git
archive`` unpacks REV outside the work tree, and two child processes, one importing REV's ``lac_rllib`` and one
today's, each build the algorithm with today's ``benchmark_fields`` (fields REV does not know are
refused there, in one line), warm up, and time one update call whenever the parent asks, the two
in turn, so that both see the same machine load. Prints the medians and REV / today.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

PATHS = ("rllib", "fused")
HOUSE = "house"  # a baseline built on another's house: that house's fused step, timed beside it


def _build(algo: str, task: str, path: str, steps: int):
    from lac_rllib.algorithms.registry import benchmark_fields, build_config

    sets = {**benchmark_fields(algo, "update_step", steps), "update_path": path}
    return build_config(algo, task, 0, sets, timesteps=10**7).build_algo()


def _timed_update(algo) -> float:
    """Seconds per gradient step of one training iteration's update call (its steps counted)."""
    learner = algo.learner_group._learner  # local learner (num_learners=0)
    counted, apply, update, seconds = [0], learner.apply_gradients, algo.learner_group.update, []

    def count(*args, **kwargs):
        counted[0] += 1
        return apply(*args, **kwargs)

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        out = update(*args, **kwargs)
        seconds.append(time.perf_counter() - t0)
        return out

    learner.apply_gradients, algo.learner_group.update = count, timed
    try:
        algo.train()
    finally:
        learner.apply_gradients, algo.learner_group.update = apply, update
    return sum(seconds) / max(counted[0], 1)


def _reference(name: str, algo, n: int):
    """The plain-torch step of ``algo``'s networks and ``n`` minibatches for it."""
    import reference_steps as R

    learner = algo.learner_group._learner
    module = learner.module["default_policy"].unwrapped()
    step = R.STEPS[name](module, learner.config)
    return step, [R.make_batch(name, module, step.minibatch_rows, seed=i) for i in range(n)]


def _timed_reference(step, batches) -> float:
    t0 = time.perf_counter()
    for b in batches:
        step.step(b)
    return (time.perf_counter() - t0) / len(batches)


def _serve(algo_name: str, task: str, sets: dict, warmup: int) -> int:
    """The child of ``--against``: builds ``algo_name`` with the ``lac_rllib`` on its path, warms it
    up, announces it, then one ms-per-step figure per request (:mod:`revision`)."""
    import ray
    import revision
    import torch

    from lac_rllib.algorithms.registry import build_config

    torch.set_num_threads(1)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    algo = build_config(algo_name, task, 0, sets, timesteps=10**7).build_algo()
    for _ in range(warmup):
        algo.train()
    revision.announce()
    for _ in revision.requests():
        print(json.dumps({"ms": 1e3 * _timed_update(algo)}), flush=True)
    algo.stop()
    return 0


def against(rev: str, algos: list[str], task: str, steps: int, repeats: int) -> list[str]:
    """Today's default step of each of ``algos`` against REV's, timed in turn (module docstring)."""
    import reference_steps
    import revision

    from lac_rllib.algorithms.registry import benchmark_fields

    lines = []
    with revision.unpacked(rev) as (short, tree):
        lines += [f"| algorithm | {short} | today | {short} / today |", "|---|---:|---:|---:|"]
        for name in algos:
            sets = benchmark_fields(name, "update_step", steps)
            warmup = reference_steps.STEPS[name].warmup_iterations(steps) if name in reference_steps.STEPS else 1
            args = ["--serve", name, "--task", task, "--sets", json.dumps(sets), "--warmup", str(warmup)]
            with revision.pair(short, tree, __file__, args) as children:
                times = {k: [] for k in children}
                for _ in range(repeats):
                    for k, reply in revision.ask(children).items():
                        times[k].append(reply["ms"])
            old, new = (statistics.median(times[k]) for k in (short, "today"))
            lines.append(f"| {name} | {old:.2f} | {new:.2f} | {old / new:.2f}x |")
            print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="SafetyPointGoal1-v0")
    parser.add_argument("--algos", default=None, help="default: every algorithm reference_steps.py has a step of, "
                        "then the first-order baselines")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--against", metavar="REV", help="time the default step of the code at git revision REV "
                        "beside today's instead (module docstring)")
    parser.add_argument("--serve", help=argparse.SUPPRESS)  # the --against children
    parser.add_argument("--sets", default="{}", help=argparse.SUPPRESS)
    parser.add_argument("--warmup", type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return _serve(args.serve, args.task, json.loads(args.sets), args.warmup)
    import reference_steps

    from lac_rllib.algorithms.registry import ALGOS, house
    from lac_rllib.tasks import get_task

    # The baselines with a plain-torch step, then those built on one of their houses (timed against it).
    built_on = {a: house(a) for a in ALGOS if a not in reference_steps.STEPS}
    accepted = (*reference_steps.STEPS, *(a for a, h in built_on.items() if h in reference_steps.STEPS))
    args.algos = args.algos or ",".join(accepted)
    try:  # bad input, before Ray starts
        get_task(args.task)
        for name in args.algos.split(","):
            if name not in accepted:
                raise ValueError(f"--algos {name!r}; accepted: {', '.join(accepted)} (the baselines; LAC's step is "
                                 "its chain's: benchmarks/langevin.py)")
        if args.steps < 10 or args.repeats < 1:
            raise ValueError(f"--steps {args.steps} / --repeats {args.repeats}; "
                             "accepted: --steps >= 10, --repeats >= 1")
    except ValueError as e:
        parser.exit(2, f"update_step: error: {e}\n")
    if args.against:
        try:
            lines = against(args.against, args.algos.split(","), args.task, args.steps, args.repeats)
        except ValueError as e:
            parser.exit(2, f"update_step: error: {e}\n")
        print(f"\nms per gradient step (medians of {args.repeats} repeats, the two in turn), one CPU, one torch thread")
        print("\n".join(lines))
        return 0
    import ray
    import reference_steps
    import torch

    torch.set_num_threads(1)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    lines = ["| algorithm | RLlib's path | fused | plain torch | matmul floor | RLlib / fused | fused / plain "
             "| fused / floor | fused / its house's fused |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name in args.algos.split(","):
        reference = name in reference_steps.STEPS
        algos = {path: _build(name, args.task, path, args.steps) for path in PATHS}
        base = built_on.get(name)
        if base:  # its house's fused step, timed in the same interleaved repeats: the ratio holds on a busy machine
            algos[HOUSE] = _build(base, args.task, "fused", args.steps)
        try:
            warmup = reference_steps.STEPS[name].warmup_iterations(args.steps) if reference else 1
            for a in algos.values():  # warm-up: SAC-Lag's random phase, first allocations
                for _ in range(warmup):
                    a.train()
            times = {path: [] for path in algos}
            plain = []
            if reference:
                step, batches = _reference(name, algos["fused"], min(args.steps, 300))
            for _ in range(args.repeats):
                for path, a in algos.items():
                    times[path].append(_timed_update(a))
                if reference:
                    plain.append(_timed_reference(step, batches))
            floor = reference_steps.matmul_seconds(step.step, batches[:50]) if reference else None
        finally:
            for a in algos.values():
                a.stop()
        rllib, fused = (1e3 * statistics.median(t) for t in (times["rllib"], times["fused"]))
        if reference:
            ref, floor = 1e3 * statistics.median(plain), 1e3 * floor
            own = f"{ref:.2f} | {floor:.2f} | {rllib / fused:.2f}x | {fused / ref:.2f}x | {fused / floor:.2f}x"
        else:
            own = f"– | – | {rllib / fused:.2f}x | – | –"
        vs_house = f"{fused / (1e3 * statistics.median(times[HOUSE])):.2f}x ({base})" if base else "–"
        lines.append(f"| {name} | {rllib:.2f} | {fused:.2f} | {own} | {vs_house} |")
        print(lines[-1], flush=True)
    print("\nms per gradient step (medians of", args.repeats, "interleaved repeats), one CPU, one torch thread")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
