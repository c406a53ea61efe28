"""Wall time of one LAC iteration, split into phases, for today's path and a baseline, same run.

    python benchmarks/iteration.py                                  # PointGoal1 and Humanoid presets
    python benchmarks/iteration.py --tasks SafetyPointGoal1-v0 --out docs/speed/iteration.md

One iteration at a task's preset (``env_steps_per_iteration`` steps sampled by the generator, then
one pass of minibatches over a full replay buffer: 195 minibatches of 256 from 50k rows, each
with a T-step chain), on one CPU (Ray with 1 CPU, ``num_env_runners=0``, one torch thread).
Before the timed iteration the buffer is filled to capacity minus one iteration with copies of
one iteration of random-action episodes, and one chain runs at the training shapes so that a
compile (``langevin_fused``) is paid before the clock starts (neither is timed): the pass has its
steady-state length and cost.

Phases (wall seconds):
- env: the envs' own ``step``/``reset`` (timed around each sub-env's calls);
- sampling machinery: the rest of the env runner's ``sample`` (RLlib connectors, episodes, actor);
- chain: the Langevin chains inside the learner;
- update: the rest of ``learner_group.update`` (learner connectors, critic/actor losses, backward,
  Adam, Polyak);
- other: the rest of ``algo.train()`` (replay buffer, weight sync, metrics).

Configurations, each built fresh on the same task, seed and buffer contents:
- ``baseline``: the path before the speed work: one env per runner, eager float32 chain, stock
  Safety-Gymnasium resets (env_config ``light_resets=False``);
- ``current``: the defaults (the preset's vector env, fused chain).
``--variant NAME:field=value,...`` adds others (e.g. ``bf16:langevin_dtype=bfloat16``).
Prints a table with each phase's ratio baseline / current and writes it to ``--out``, then the
float32 matmul floor of the current iteration's chains, timed in the same run, and the ratio an
iteration would reach with the chain exactly at that floor (the ceiling of float32 on this CPU).

``--cpus 2`` times the whole iteration of the current configuration (and of each ``--variant``),
phase by phase, on one CPU and on two (``lac-train --cpus 2``: two env runners sample, two torch
threads update; lac_rllib.constrained.cpus.use_cpus), same buffer, same run, and prints the ratio
(issue 24's goal: >= 1.6x). With ``--algos`` too: each algorithm's seconds per ``--steps`` env
steps on one CPU and on N, and their ratio.

``--algos lac,ppo_lag,sac_lag`` times each algorithm at the task's preset on one CPU, same run:
seconds per ``--steps`` env steps (default 20k) of training after a warm-up of as many (LAC with its
random phase and the actor's delay off, SAC-Lag's random steps within the warm-up), and for the
off-policy ones the share of RLlib's per-call overhead (one ``learner_group.update`` per iteration:
the calls times the cost of an update call of one minibatch, measured in the same run).

``--algos ppo_lag,sac_lag --update-paths`` times the baselines' whole training iterations on
RLlib's update path and on the fused one (``update_path``: the same updates bit for bit), same
run, one CPU, interleaved iteration by iteration after a warm-up, and prints the ratio.

``--algos ppo_lag --against REV`` times instead each algorithm's whole training iterations in the
code at git revision ``REV`` (say, the commit an issue was filed against) beside today's default,
same run (:mod:`revision`): two child processes, one importing REV's ``lac_rllib`` and one today's,
each build the algorithm at the task's preset from the same seed (one CPU, one torch thread), train
through a warm-up of ``--steps`` env steps, then train one iteration whenever the parent asks, the
two in turn, until each has timed ``--steps``; prints seconds per ``--steps`` env steps and REV / today,
and the rows each side trained per env step (PPO-Lag's KL early stop cuts an iteration's epochs
where the policy moved far: two revisions whose runs part do different amounts of work, so a
ratio is read beside that column, and a longer ``--steps`` averages over more iterations).
"""

from __future__ import annotations

import argparse
import collections
import copy
import functools
import sys
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

PHASES = ("env", "sampling machinery", "chain", "update", "other", "total")
BASELINE = {"num_envs_per_env_runner": 1, "langevin_fused": False, "langevin_dtype": "float32"}
BASELINE_ENV_CONFIG = {"light_resets": False}  # stock Safety-Gymnasium resets
DEFAULT_TASKS = ("SafetyPointGoal1-v0", "focops/HumanoidVelocity-v0")


class _Clock:
    """Accumulates wall time of wrapped callables by phase name."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    def wrap(self, name: str, fn):
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0

        return timed


def _sub_envs(runner):
    env = runner.env
    while not hasattr(env, "envs"):  # RLlib's DictInfoToList around gymnasium's SyncVectorEnv
        env = env.env
    return env.envs


def prefill_episodes(task: str, seed: int):
    """One iteration of random-action episodes at the preset (copied to fill the buffer)."""
    from lac_rllib.algorithms.lac.config import LACConfig

    config = LACConfig.build(task, seed, {"num_envs_per_env_runner": 1}, timesteps=10**9)
    algo = config.build_algo()
    try:
        episodes = algo.env_runner.sample(num_timesteps=config.env_steps_per_iteration, random_actions=True)
        for e in episodes:
            e.extra_model_outputs.clear()
        # The filtered observations in these episodes were normalised by this runner's filter;
        # hand its state over with them, as a resumed run would.
        return episodes, algo.env_runner.get_state(), config.replay_capacity, config.env_steps_per_iteration
    finally:
        algo.stop()


def _warm_up_chain(algo, config) -> None:
    """One chain at the training shapes, so a compile (langevin_fused) is not timed as work."""
    import torch
    from ray.rllib.core import DEFAULT_MODULE_ID

    module = algo.learner_group._learner.module[DEFAULT_MODULE_ID]
    obs = torch.zeros(config.lac_minibatch_size, module.actor.mean_net[0].in_features)
    with torch.no_grad():
        mean, log_std = module.target_actor(obs)
        module.langevin(obs, mean, log_std)


def chain_matmul_floor_s(critics, calls: list[tuple[int, int]], repeats: int = 3) -> float:
    """Seconds the chains' dense matmuls alone take in float32: per step, each hidden-to-hidden
    layer's batched (E, B, H)×(E, H, H) once forward and once backward, plus one forward for the
    final energy; ``calls`` are the chains run, as (batch, steps). The floor of the chain's form:
    no element-wise work, no overhead (benchmarks/langevin.py measures the same per chain)."""
    import torch

    shapes = [tuple(w.shape) for w in list(critics.weights)[1:-1]]  # (E, H_in, H_out)
    total = 0.0
    for (batch, steps), n in collections.Counter(calls).items():
        xs = [torch.randn(e, batch, h_in) for e, h_in, _ in shapes]
        ws = [torch.randn(*shape) for shape in shapes]
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(2 * steps + 1):
                for x, w in zip(xs, ws):
                    torch.bmm(x, w)
            best = min(best, time.perf_counter() - t0)
        total += n * best
    return total


def time_iteration(task: str, sets: dict, seed: int, prefill, env_config: dict | None = None) -> dict[str, float]:
    """Seconds per phase of one ``algo.train()`` with ``sets`` on top of the defaults, and
    ``chain floor``: the float32 matmul floor of the same chains (:func:`chain_matmul_floor_s`)."""
    import lac_rllib.algorithms.lac.module as module_mod
    from lac_rllib.algorithms.lac.config import LACConfig

    episodes, runner_state, capacity, per_iteration = prefill
    sets = {"random_iterations": 0, "actor_update_start_iteration": 0, **sets}
    config = LACConfig.build(task, seed, sets, timesteps=10**9)
    if env_config:
        config.environment(env_config={**config.env_config, **env_config})
    algo = config.build_algo()
    clock = _Clock()
    original_chain = module_mod.langevin_chain
    try:
        algo.env_runner.set_state({k: v for k, v in runner_state.items() if "connector" in k})
        rows = 0
        while rows < capacity - per_iteration:  # copies with fresh ids: the buffer's steady state
            for e in episodes:
                dup = copy.deepcopy(e)
                dup.id_ = uuid.uuid4().hex
                algo.replay_buffer.add([dup])
                rows += len(dup)
        _warm_up_chain(algo, config)
        for env in _sub_envs(algo.env_runner):
            env.step, env.reset = clock.wrap("env", env.step), clock.wrap("env", env.reset)
        algo.env_runner.sample = clock.wrap("sampling", algo.env_runner.sample)
        algo.learner_group.update = clock.wrap("learner", algo.learner_group.update)
        calls = []

        def chain(critics, obs, mean, log_std, nu, settings, **kwargs):
            calls.append((obs.shape[0], settings.steps))
            return original_chain(critics, obs, mean, log_std, nu, settings, **kwargs)

        module_mod.langevin_chain = clock.wrap("chain", chain)
        t0 = time.perf_counter()
        algo.train()
        total = time.perf_counter() - t0
        from ray.rllib.core import DEFAULT_MODULE_ID

        floor = chain_matmul_floor_s(algo.learner_group._learner.module[DEFAULT_MODULE_ID].critics, calls)
    finally:
        module_mod.langevin_chain = original_chain
        algo.stop()
    s = clock.seconds
    return {"env": s["env"], "sampling machinery": s["sampling"] - s["env"], "chain": s["chain"],
            "update": s["learner"] - s["chain"], "other": total - s["sampling"] - s["learner"], "total": total,
            "chain floor": floor, "chains": len(calls)}


CPU_PHASES = ("sampling", "chain", "update", "other", "total")


def time_cpus(task: str, cpus: int, seed: int, prefill, iterations: int = 2, sets: dict | None = None) -> dict:
    """Mean wall seconds per phase of ``iterations`` whole ``algo.train()`` calls (after one untimed,
    which pays the compile and the runners' start) of the current defaults (and ``sets``) on ``cpus`` CPUs, the
    buffer prefilled as in :func:`time_iteration`. Phases: sampling (``sample_into_replay``: the env
    runners' sample, remote on N > 1 CPUs, and the buffer's add), chain (the Langevin chains inside
    the learner, which is local), update (the rest of ``learner_group.update``), other (the rest)."""
    import lac_rllib.algorithms.lac.module as module_mod
    from lac_rllib.algorithms.lac.config import LACConfig

    episodes, runner_state, capacity, per_iteration = prefill
    config = LACConfig.build(task, seed, {"random_iterations": 0, "actor_update_start_iteration": 0, **(sets or {})},
                          timesteps=10**9, cpus=cpus)
    algo = config.build_algo()
    original_chain = module_mod.langevin_chain
    try:
        filter_state = {k: v for k, v in runner_state.items() if "connector" in k}
        algo.env_runner_group.foreach_env_runner(lambda r: r.set_state(filter_state), local_env_runner=True)
        rows = 0
        while rows < capacity - per_iteration:
            for e in episodes:
                dup = copy.deepcopy(e)
                dup.id_ = uuid.uuid4().hex
                algo.replay_buffer.add([dup])
                rows += len(dup)
        algo.train()  # untimed: the compile, the runners' first sample
        clock = _Clock()
        algo.sample_into_replay = clock.wrap("sampling", algo.sample_into_replay)
        algo.learner_group.update = clock.wrap("learner", algo.learner_group.update)
        module_mod.langevin_chain = clock.wrap("chain", original_chain)
        t0 = time.perf_counter()
        for _ in range(iterations):
            algo.train()
        total = time.perf_counter() - t0
    finally:
        module_mod.langevin_chain = original_chain
        algo.stop()
    s = {k: v / iterations for k, v in clock.seconds.items()}
    total /= iterations
    return {"sampling": s["sampling"], "chain": s["chain"], "update": s["learner"] - s["chain"],
            "other": total - s["sampling"] - s["learner"], "total": total}


def cpus_table(task: str, cpus: int, one: dict[str, float], many: dict[str, float]) -> str:
    """The phases on 1 and ``cpus`` CPUs and their ratios (markdown)."""
    lines = [f"### {task}", "", f"| phase | 1 CPU (s) | {cpus} CPUs (s) | ratio |", "|---|---:|---:|---:|"]
    for phase in CPU_PHASES:
        ratio = one[phase] / many[phase] if many[phase] > 0 else float("nan")
        name = f"**{phase}**" if phase == "total" else phase
        lines.append(f"| {name} | {one[phase]:.1f} | {many[phase]:.1f} | {ratio:.2f}x |")
    lines += ["", f"Whole iteration, the defaults: {one['total']:.1f} s on 1 CPU, {many['total']:.1f} s on "
              f"{cpus} CPUs: {one['total'] / many['total']:.2f}x."]
    return "\n".join(lines)


def time_algorithm(algo: str, task: str, seed: int, steps: int, cpus: int = 1, threads: int = 1) -> dict[str, float]:
    """Seconds of ``algo``'s training over ``steps`` env steps after a warm-up of ``steps``, its
    update calls, and the seconds of one update call of one minibatch (RLlib's per-call overhead
    plus one step); on ``cpus`` CPUs (lac-train --cpus), or with ``threads`` learner threads."""
    from lac_rllib.algorithms.registry import benchmark_fields, build_config

    sets = benchmark_fields(algo, "iteration", steps)
    if threads > 1:
        sets = {**sets, "torch_threads": threads}
    config = build_config(algo, task, seed, sets, timesteps=10**9, cpus=cpus)
    algo_obj = config.build_algo()
    try:
        def lifetime():
            return algo_obj.metrics.peek(("env_runners", "num_env_steps_sampled_lifetime"), default=0)

        while lifetime() < steps:
            algo_obj.train()
        calls = [0]
        update = algo_obj.learner_group.update

        def counted(*args, **kwargs):
            calls[0] += 1
            return update(*args, **kwargs)

        algo_obj.learner_group.update = counted
        start, t0 = lifetime(), time.perf_counter()
        while lifetime() < start + steps:
            algo_obj.train()
        seconds, done = time.perf_counter() - t0, lifetime() - start
        algo_obj.learner_group.update = update
        per_call = float("nan")
        if hasattr(algo_obj, "replay_buffer"):  # one update call of one minibatch, timed
            t1 = time.perf_counter()
            algo_obj.update_from_replay(minibatch_size=256, num_total_minibatches=1, timesteps={})
            per_call = time.perf_counter() - t1
    finally:
        algo_obj.stop()
    return {"seconds": seconds * steps / done, "calls": calls[0] * steps / done, "per_call_s": per_call}


def time_update_paths(algo: str, task: str, seed: int, steps: int) -> dict[str, float]:
    """Seconds per ``steps`` env steps of ``algo``'s training on each update path, the two built
    from one seed and stepped iteration by iteration in turn (the machine's load falls on both)."""
    from lac_rllib.algorithms.registry import benchmark_fields, build_config

    sets = benchmark_fields(algo, "iteration", steps)
    algos = {path: build_config(algo, task, seed, {**sets, "update_path": path}, timesteps=10**9).build_algo()
             for path in ("rllib", "fused")}
    seconds = dict.fromkeys(algos, 0.0)
    try:
        def lifetime(a):
            return a.metrics.peek(("env_runners", "num_env_steps_sampled_lifetime"), default=0)

        for a in algos.values():  # warm-up (SAC-Lag: its random steps)
            while lifetime(a) < steps:
                a.train()
        start = {p: lifetime(a) for p, a in algos.items()}
        while min(lifetime(a) - start[p] for p, a in algos.items()) < steps:
            for p, a in algos.items():
                t0 = time.perf_counter()
                a.train()
                seconds[p] += time.perf_counter() - t0
        return {p: seconds[p] * steps / (lifetime(a) - start[p]) for p, a in algos.items()}
    finally:
        for a in algos.values():
            a.stop()


def table(task: str, results: dict[str, dict[str, float]]) -> str:
    names = list(results)
    lines = [f"### {task}", "", "| phase | " + " | ".join(f"{n} (s)" for n in names) + " | baseline / current |",
             "|---|" + "---:|" * (len(names) + 1)]
    for phase in PHASES:
        vals = [results[n][phase] for n in names]
        now = results["current"][phase]
        ratio = results["baseline"][phase] / now if now > 0 else float("nan")
        lines.append(f"| {phase} | " + " | ".join(f"{v:.1f}" for v in vals) + f" | {ratio:.2f}x |")
    cur, base = results["current"], results["baseline"]
    at_floor = cur["total"] - cur["chain"] + cur["chain floor"]
    lines += ["", f"Chains in the iteration: {cur['chains']}; their float32 matmul floor (the dense matmuls "
              f"alone, same run): {cur['chain floor']:.1f} s, the current chain at "
              f"{100 * cur['chain floor'] / cur['chain']:.0f}% of it. With the chain exactly at that floor and "
              f"every other phase as measured, an iteration would take {at_floor:.1f} s: at most "
              f"{base['total'] / at_floor:.2f}x the baseline in float32 on this CPU."]
    return "\n".join(lines)


def _write(path: str | None, lines: list[str]) -> None:
    """The tables (markdown) to ``--out``, if given."""
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text("\n".join(lines))


def _serve(algo: str, task: str, seed: int, steps: int) -> int:
    """The child of ``--against``: builds ``algo`` with the ``lac_rllib`` on its path, trains
    through ``steps`` env steps of warm-up, announces it, then trains one iteration per request and
    answers its seconds, env steps and rows trained (:mod:`revision`)."""
    import json

    import ray
    import revision
    import torch

    from lac_rllib.algorithms.registry import build_config

    torch.set_num_threads(1)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    algo_obj = build_config(algo, task, seed, {}, timesteps=10**9).build_algo()

    def lifetime():
        return algo_obj.metrics.peek(("env_runners", "num_env_steps_sampled_lifetime"), default=0)

    def trained():  # rows through gradient steps (minibatch rows, every epoch), as RLlib counts them
        return algo_obj.metrics.peek(("learners", "__all_modules__", "num_module_steps_trained_lifetime"), default=0)

    while lifetime() < steps:
        algo_obj.train()
    revision.announce()
    for _ in revision.requests():
        start, rows, t0 = lifetime(), trained(), time.perf_counter()
        algo_obj.train()
        print(json.dumps({"s": time.perf_counter() - t0, "steps": lifetime() - start, "trained": trained() - rows}),
              flush=True)
    algo_obj.stop()
    return 0


def time_against(rev: str, algos: list[str], task: str, seed: int, steps: int) -> list[str]:
    """Seconds per ``steps`` env steps of each of ``algos`` at REV and today, iterations in turn."""
    import revision

    with revision.unpacked(rev) as (short, tree):
        lines = [f"| algorithm | s per {steps:,} env steps, {short} | today | {short} / today | iterations timed "
                 f"| rows trained per env step, {short} / today |",
                 "|---|---:|---:|---:|---:|---:|"]
        for a in algos:
            args = ["--serve", a, "--tasks", task, "--seed", str(seed), "--steps", str(steps)]
            with revision.pair(short, tree, __file__, args) as children:
                seconds, done, rows, n = (dict.fromkeys(children, 0.0), dict.fromkeys(children, 0),
                                          dict.fromkeys(children, 0), 0)
                while min(done.values()) < steps:
                    for k, reply in revision.ask(children).items():
                        seconds[k] += reply["s"]
                        done[k] += reply["steps"]
                        rows[k] += reply.get("trained", 0)
                    n += 1
            old, new = (seconds[k] * steps / done[k] for k in (short, "today"))
            work = " / ".join(f"{rows[k] / done[k]:.1f}" for k in (short, "today"))
            lines.append(f"| {a} | {old:.2f} | {new:.2f} | {old / new:.2f}x | {n} each | {work} |")
            print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="+", default=None,
                        help=f"default: {' '.join(DEFAULT_TASKS)} (with --against: the first)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--variant", action="append", default=[], metavar="NAME:F=V,...",
                        help="another configuration to time (lac-train --set syntax)")
    parser.add_argument("--out", default=None, help="also write the tables (markdown) here")
    parser.add_argument("--algos", default=None, metavar="A,B,...",
                        help="instead of the phases: seconds per --steps env steps of each algorithm, one CPU")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps timed per algorithm (--algos)")
    parser.add_argument("--update-paths", action="store_true",
                        help="with --algos: the baselines' iterations on update_path rllib against fused")
    parser.add_argument("--cpus", type=int, default=None, metavar="N",
                        help="instead of the phases: whole iterations on 1 CPU against N CPUs, and their ratio")
    parser.add_argument("--against", metavar="REV", help="with --algos: whole iterations of the code at git "
                        "revision REV beside today's (module docstring)")
    parser.add_argument("--serve", help=argparse.SUPPRESS)  # the --against children
    args = parser.parse_args(argv)
    args.tasks = args.tasks or list(DEFAULT_TASKS[:1] if args.against or args.serve else DEFAULT_TASKS)
    if args.serve:
        return _serve(args.serve, args.tasks[0], args.seed, args.steps)
    from lac_rllib.algorithms.lac.config import FIELDS as LAC_FIELDS
    from lac_rllib.tasks import get_task

    variants = {"baseline": BASELINE, "current": {}}
    try:
        if args.cpus is not None and args.cpus < 1:
            raise ValueError(f"--cpus {args.cpus}; accepted: an integer >= 1")
        for task in args.tasks:
            get_task(task)
        for text in args.variant:
            name, _, pairs = text.partition(":")
            variants[name] = LAC_FIELDS.parse_sets([p for p in pairs.split(",") if p])
        if args.update_paths:
            from lac_rllib.algorithms.registry import algo_config

            for a in (args.algos or "").split(","):
                if "update_path" not in algo_config(a).FIELDS.names:
                    raise ValueError(f"--update-paths with --algos {a!r}: it has no update_path; accepted: "
                                     "the baselines that have (ppo_lag, sac_lag)")
        if args.against:
            from lac_rllib.algorithms.registry import ALGOS

            if not args.algos or any(a not in ALGOS for a in args.algos.split(",")):
                raise ValueError(f"--against needs --algos, each one of: {', '.join(ALGOS)} (got {args.algos!r})")
            if len(args.tasks) != 1:
                raise ValueError(f"--against times one task; got --tasks {' '.join(args.tasks)}")
            import revision

            with revision.unpacked(args.against):  # a revision that is not a commit: refused here
                pass
    except ValueError as e:
        parser.exit(2, f"iteration: error: {e}\n")

    if args.against:
        lines = time_against(args.against, args.algos.split(","), args.tasks[0], args.seed, args.steps)
        out = [f"Whole training iterations, one CPU, one torch thread, the two in turn after a warm-up of "
               f"{args.steps:,} env steps; {args.tasks[0]}, seed {args.seed}.", "", *lines]
        print("\n".join(out))
        _write(args.out, out)
        return 0
    import ray
    import torch

    from lac_rllib.tasks.versions import runtime_versions

    torch.set_num_threads(1)
    ray.init(num_cpus=args.cpus or 1, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    what = f"on 1 and {args.cpus} CPUs" if args.cpus else "one CPU"
    out = [f"One LAC iteration per configuration, {what}. {runtime_versions()}, "
           f"torch {torch.__version__}, CPU capability {torch.backends.cpu.get_cpu_capability()}.", ""]
    if args.algos and args.update_paths:
        for task in args.tasks:
            lines = [f"### {task}", "", f"| algorithm | s per {args.steps:,} env steps, update_path rllib | fused | "
                     "ratio |", "|---|---:|---:|---:|"]
            for a in args.algos.split(","):
                t = time_update_paths(a, task, args.seed, args.steps)
                lines.append(f"| {a} | {t['rllib']:.1f} | {t['fused']:.1f} | {t['rllib'] / t['fused']:.2f}x |")
                print(lines[-1], flush=True)
            out += [*lines, ""]
        print("\n".join(out))
        _write(args.out, out)
        return 0
    if args.algos and args.cpus:
        for task in args.tasks:
            lines = [f"### {task}", "", f"| algorithm | s per {args.steps:,} env steps, 1 CPU | {args.cpus} CPUs | "
                     "ratio |", "|---|---:|---:|---:|"]
            for a in args.algos.split(","):
                one = time_algorithm(a, task, args.seed, args.steps)["seconds"]
                try:
                    many, how = time_algorithm(a, task, args.seed, args.steps, cpus=args.cpus)["seconds"], ""
                except ValueError:  # its envs do not split over the runners: the learner's threads only
                    many = time_algorithm(a, task, args.seed, args.steps, threads=args.cpus)["seconds"]
                    how = f" (one env runner, {args.cpus} learner threads: its envs do not split)"
                lines.append(f"| {a}{how} | {one:.1f} | {many:.1f} | {one / many:.2f}x |")
                print(lines[-1], flush=True)  # progress; the table follows
            out += [*lines, ""]
        print("\n".join(out))
        _write(args.out, out)
        return 0
    if args.algos:
        for task in args.tasks:
            lines = [f"### {task}", "", f"| algorithm | s per {args.steps:,} env steps | / LAC | update calls | "
                     "per-call overhead share |", "|---|---:|---:|---:|---:|"]
            from lac_rllib.algorithms.registry import DEFAULT_ALGO

            times = {a: time_algorithm(a, task, args.seed, args.steps) for a in args.algos.split(",")}
            for a, r in times.items():
                share = r["calls"] * r["per_call_s"] / r["seconds"] if r["per_call_s"] == r["per_call_s"] else None
                lac = times.get(DEFAULT_ALGO, {}).get("seconds")
                lines.append(f"| {a} | {r['seconds']:.1f} | {r['seconds'] / lac:.2f}x | {r['calls']:.0f} | "
                             + ("–" if share is None else f"≤ {share:.1%}") + " |" if lac else
                             f"| {a} | {r['seconds']:.1f} | – | {r['calls']:.0f} | – |")
            print("\n".join(lines) + "\n", flush=True)
            out += [*lines, ""]
        _write(args.out, out)
        return 0
    if args.cpus:
        # The current defaults, then each --variant (e.g. bf16:langevin_dtype=bfloat16), on 1 and N CPUs.
        for task in args.tasks:
            prefill = prefill_episodes(task, args.seed)
            for name, sets in variants.items():
                if name == "baseline":
                    continue
                one, many = (time_cpus(task, n, args.seed, prefill, sets=sets) for n in (1, args.cpus))
                text = cpus_table(f"{task}, {name}", args.cpus, one, many)
                print(text + "\n", flush=True)
                out += [text, ""]
        _write(args.out, out)
        return 0
    for task in args.tasks:
        prefill = prefill_episodes(task, args.seed)
        results = {}
        for name, sets in variants.items():
            results[name] = time_iteration(task, sets, args.seed, prefill,
                                           BASELINE_ENV_CONFIG if name == "baseline" else None)
            print(f"{task} {name}: " + ", ".join(f"{k} {v:.1f}s" for k, v in results[name].items()
                                                 if k in PHASES), flush=True)
        text = table(task, results)
        print("\n" + text + "\n", flush=True)
        out += [text, ""]
    _write(args.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
