"""Timing of the Langevin chain (Algorithm 1): efficient form vs naive full-autograd form.

    python benchmarks/langevin.py

Prints ms per chain (batch 256, T = 30, paper hyper-parameters η = 1e-4, λ = 1e-3) at
PointGoal1 and Humanoid sizes with the default networks (actor 256×256 tanh, critics 3×256
Mish, 2 reward + 2 cost). "efficient" = one target-actor forward + ``langevin_chain`` (state
projection and (μ, σ) once, batched manual backward); "naive" = ``naive_langevin_chain``
(autograd through the full critics and a fresh actor forward every step). Both include the
final energy evaluation. Median over interleaved repeats after warm-up. No asserts: figures only.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from lac_rllib.langevin import langevin_chain, naive_langevin_chain  # noqa: E402
from lac_rllib.networks import CriticEnsemble, GaussianActor  # noqa: E402

TASK_DIMS = {"PointGoal1": (60, 2), "Humanoid": (376, 17)}
CHAIN = dict(steps=30, step_size=1e-4, temperature=1e-3, nu=0.5)


def _interleaved_median_ms(fns: dict, repeats: int, warmup: int = 2) -> dict:
    """Median ms per call; the candidates alternate so that load from other processes on a
    shared machine hits them alike instead of biasing whichever ran during a busy spell."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(1e3 * (time.perf_counter() - t0))
    return {name: statistics.median(t) for name, t in times.items()}


def _chain_case(obs_dim: int, act_dim: int, batch: int, repeats: int) -> dict:
    torch.manual_seed(0)
    critics = CriticEnsemble(obs_dim, act_dim)
    actor = GaussianActor(obs_dim, act_dim)
    obs = torch.randn(batch, obs_dim)
    steps = CHAIN["steps"]
    noise = torch.randn(steps + 1, batch, act_dim)
    low, high = -torch.ones(act_dim), torch.ones(act_dim)

    def efficient():
        with torch.no_grad():
            mean, log_std = actor(obs)
        return langevin_chain(critics, obs, mean, log_std, noise=noise, low=low, high=high,
                              **CHAIN)

    def naive():
        with torch.no_grad():
            mean, log_std = actor(obs)
            a0 = mean + log_std.exp() * noise[0]
        return naive_langevin_chain(critics, actor, obs, a0, logp_weight=1.0, low=low,
                                    high=high, noise=noise[1:], **CHAIN)

    diff = (efficient().action - naive().action).abs().max().item()
    ms = _interleaved_median_ms({"efficient": efficient, "naive": naive}, repeats)
    fast_ms, slow_ms = ms["efficient"], ms["naive"]
    return dict(efficient=fast_ms, naive=slow_ms, ratio=slow_ms / fast_ms, max_diff=diff)


def bench_chain(batch: int = 256, repeats: int = 9, threads: list[int] | None = None) -> list[dict]:
    """ms per Langevin chain, efficient vs naive, for each task size and thread setting
    (default: 1 thread and torch's default)."""
    default_threads = torch.get_num_threads()
    thread_settings = threads or sorted({1, default_threads})
    rows = []
    print(f"\nLangevin chain: batch {batch}, T = {CHAIN['steps']}, float32, "
          f"median of {repeats} (ms per chain)")
    header = f"{'task':<11} {'obs/act':>8} {'threads':>7} {'efficient':>10} {'naive':>9} " \
             f"{'naive/eff':>9} {'max|Δa|':>9}"
    print(header)
    print("-" * len(header))
    try:
        for threads in thread_settings:
            torch.set_num_threads(threads)
            for task, (obs_dim, act_dim) in TASK_DIMS.items():
                r = _chain_case(obs_dim, act_dim, batch, repeats)
                r.update(task=task, obs_dim=obs_dim, act_dim=act_dim, threads=threads)
                rows.append(r)
                print(f"{task:<11} {f'{obs_dim}/{act_dim}':>8} {threads:>7} "
                      f"{r['efficient']:>10.2f} {r['naive']:>9.2f} {r['ratio']:>8.2f}x "
                      f"{r['max_diff']:>9.1e}", flush=True)
    finally:
        torch.set_num_threads(default_threads)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=lambda s: [int(x) for x in s.split(",")], default=None,
                        help="comma-separated torch thread counts (default: 1 and torch's default)")
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args()
    print(f"torch {torch.__version__}, default threads {torch.get_num_threads()}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} "
          "(multi-thread timings collapse when other work holds the cores)")
    bench_chain(repeats=args.repeats, threads=args.threads)


if __name__ == "__main__":
    main()
