"""Running one constrained algorithm's run on several CPUs: the same algorithm (sample, then update,
each iteration), its env runners and torch threads scaled together, for lac-train ``--cpus`` and a
sweep's ``--cpus-per-trial``. The config has ``num_envs_per_env_runner`` and ``torch_threads``.
"""

from __future__ import annotations

import torch
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.utils.annotations import override


class OneThreadPerEnvRunner(RLlibCallback):
    """Each remote env runner's torch ops on one thread, whatever ``OMP_NUM_THREADS`` the run was
    started with. Ray hands its actors the driver's ``OMP_NUM_THREADS`` when it is set, and a run
    on 2 CPUs started with 2 spun two OpenMP threads per runner: four threads on two cores, half the
    time in the kernel, 72-77 s per PointGoal1 iteration against 40-45 s (docs/speed.md). Set in
    each runner when its env is made (RLlib's per-runner hook); the driver's own runner (no remote
    runners) keeps the learner's ``torch_threads``."""

    @override(RLlibCallback)
    def on_environment_created(self, *, env_runner, **kwargs) -> None:
        if env_runner.worker_index > 0:
            torch.set_num_threads(1)


def learner_torch(threads: int, flush_denormal: bool = False) -> None:
    """The learner process's torch: ``threads`` intra-op threads, and fresh tensors left unfilled.
    RLlib's seeding turns on torch's deterministic algorithms (``set_torch_seed``), and with them
    torch fills every tensor ``torch.empty`` makes (each dtype cast among them) with NaN, a write
    that only shows in code reading memory it never wrote. Off, every seeded run repeats as before,
    bit for bit, and a gradient step is 2-6% faster (PPO-Lag's 64-row one most: docs/speed.md).
    Every learner's ``build`` calls it. ``flush_denormal``: denormal floats flushed to zero in this
    process (``torch.set_flush_denormal``; it changes bits: a field of the algorithm's, off unless
    set; the process's env runner, when it samples in the driver, flushes too)."""
    torch.set_num_threads(threads)
    torch.utils.deterministic.fill_uninitialized_memory = False
    torch.set_flush_denormal(flush_denormal)  # set either way: a process may build several learners


def set_runners(config, num_env_runners: int, cpus: int) -> None:
    """``num_env_runners`` remote env runners (0: sample in the driver), or the run on ``cpus`` CPUs
    (:func:`use_cpus`); not both (every algorithm's ``build_config``)."""
    config.env_runners(num_env_runners=num_env_runners)
    if cpus != 1:  # use_cpus refuses 0 or a count that does not split the envs
        if num_env_runners:
            raise ValueError(f"--cpus {cpus} with --num-env-runners {num_env_runners}: the CPUs set the env runners; "
                             "accepted: one of the two")
        use_cpus(config, cpus)


def use_cpus(config, cpus: int) -> None:
    """Sample with ``cpus`` env runners and update with ``cpus`` torch threads: the same algorithm
    (sample, then update, each iteration) on more CPUs. The envs of an iteration stay the same:
    ``num_envs_per_env_runner`` envs split evenly over the runners (10 → 2 × 5), so an iteration
    holds the same episodes, and ν (eq. 14) reads as many completed ones, as on one CPU. Sampling
    and updating take turns, so the run reserves ``cpus`` CPUs in all: 1 for the driver and its
    learner, (cpus − 1)/cpus for each runner (:func:`run_resources` for a Tune trial)."""
    envs = config.num_envs_per_env_runner
    check_cpus(envs, cpus)
    if cpus == 1:
        return
    config.env_runners(num_env_runners=cpus, num_envs_per_env_runner=envs // cpus,
                       num_cpus_per_env_runner=runner_cpus(cpus))
    config.training(torch_threads=cpus)


def runner_cpus(cpus: int) -> float:
    """The CPU share each of a ``cpus``-CPU run's env runners reserves (the driver reserves 1)."""
    return (cpus - 1) / cpus


def run_resources(cpus: int):
    """What a Tune trial of a ``cpus``-CPU run reserves: the driver's bundle (it holds the learner)
    and one bundle per env runner, which RLlib places its runners in (``cpus`` CPUs in all)."""
    from ray.tune import PlacementGroupFactory

    if cpus == 1:
        return {"cpu": 1}
    return PlacementGroupFactory([{"CPU": 1.0}] + [{"CPU": runner_cpus(cpus)}] * cpus)


def check_cpus(envs: int, cpus: int, flag: str = "--cpus") -> None:
    """Raise a ValueError naming the accepted CPU counts unless ``envs`` envs split evenly over ``cpus``."""
    if not (isinstance(cpus, int) and cpus >= 1) or envs % cpus:
        divisors = ", ".join(str(d) for d in range(1, envs + 1) if envs % d == 0)
        raise ValueError(f"{flag} {cpus} is invalid with num_envs_per_env_runner={envs}: the envs must split evenly "
                         f"over the env runners; accepted: {divisors} (or --set num_envs_per_env_runner=...)")
