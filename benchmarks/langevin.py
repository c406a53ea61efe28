"""Timing of the Langevin chain (Algorithm 1): our forms against the authors' and the matmul floor.

    python benchmarks/langevin.py [--dtypes float32,bfloat16]

Prints ms per chain (batch 256, T = 30, paper hyper-parameters η = 1e-4, λ = 1e-3) at
PointGoal1 and Humanoid sizes with the default networks (actor 256×256 tanh, critics 3×256
Mish, 2 reward + 2 cost), all in one run, interleaved:
- "eager" = one target-actor forward + ``langevin_chain`` (state projection and (μ, σ) once,
  batched hand-written backward), the path before ``langevin_fused``;
- "fused" = the same with ``fused=True`` (torch.compile of each step's energy gradient; the
  default), and "fused bf16" with the matmuls in bfloat16 (``langevin_dtype``);
- "naive" = ``naive_langevin_chain`` (autograd w.r.t. the action through the full critics and a
  fresh actor forward every step); "authors" = the same but ``backward()`` into the parameters'
  gradients too, as the authors' code does;
- "floor" = the chain's dense matmuls alone in that dtype (4 batched (E,B,H)×(E,H,H) per step,
  2 more for the final energy), and fused / floor as "% of floor" (the issue's target is 70%).
All include the final energy evaluation. Median over interleaved repeats after warm-up (the
compile happens in the warm-up). No asserts: figures only.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from lac_rllib.algorithms.lac.langevin import ChainSettings, langevin_chain, naive_langevin_chain
from lac_rllib.constrained.networks import CriticEnsemble, GaussianActor, cost_rows, reward_rows

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


def _chain_case(obs_dim: int, act_dim: int, batch: int, repeats: int, dtypes: list[str]) -> dict:
    torch.manual_seed(0)
    critics = CriticEnsemble(obs_dim, act_dim)
    actor = GaussianActor(obs_dim, act_dim)
    obs = torch.randn(batch, obs_dim)
    steps = CHAIN["steps"]
    noise = torch.randn(steps + 1, batch, act_dim)
    low, high = -torch.ones(act_dim), torch.ones(act_dim)

    def ours(fused: bool, dtype: str = "float32"):
        def run():
            with torch.no_grad():
                mean, log_std = actor(obs)
            settings = ChainSettings(low=low, high=high, fused=fused, dtype=dtype,
                                     **{k: v for k, v in CHAIN.items() if k != "nu"})
            return langevin_chain(critics, obs, mean, log_std, CHAIN["nu"], settings, noise=noise)
        return run

    def naive(param_grads: bool):
        def run():
            with torch.no_grad():
                mean, log_std = actor(obs)
                a0 = mean + log_std.exp() * noise[0]
            if not param_grads:
                return naive_langevin_chain(critics, actor, obs, a0, logp_weight=1.0, low=low,
                                            high=high, noise=noise[1:], **CHAIN)
            return _authors_chain(critics, actor, obs, a0, noise[1:], low, high)
        return run

    def floor(dtype: str):
        n = critics.n_members
        x = torch.randn(n, batch, 256).to(getattr(torch, dtype))
        w = torch.randn(n, 256, 256).to(x.dtype)

        def run():
            for _ in range(4 * steps + 2):
                torch.bmm(x, w)
        return run

    fns = {"eager": ours(False), "fused": ours(True), "naive": naive(False), "authors": naive(True)}
    if "bfloat16" in dtypes:
        fns["fused bf16"] = ours(True, "bfloat16")
    for dtype in dtypes:
        fns[f"floor {dtype}"] = floor(dtype)
    diff = (fns["fused"]().action - fns["naive"]().action).abs().max().item()
    ms = _interleaved_median_ms(fns, repeats)
    ms["max_diff"] = diff
    ms["% of floor"] = 100 * ms["floor float32"] / ms["fused"]
    return ms


def _authors_chain(critics, actor, obs, a0, noise, low, high):
    """The authors' step: autograd of the energy through the critics into the action AND every
    parameter (``energy.sum().backward()``), a fresh actor forward each step."""
    a = a0.clone()
    nr = critics.n_reward
    for z in noise:
        a.requires_grad_(True)
        mean, log_std = actor(obs)
        q = critics(obs, a)
        logp = torch.distributions.Normal(mean, log_std.exp()).log_prob(a).sum(-1)
        q_r, q_c = reward_rows(q, nr), cost_rows(q, nr)
        energy = (CHAIN["nu"] * q_c.max(0).values - q_r.min(0).values) / CHAIN["temperature"] - logp
        energy.sum().backward()
        with torch.no_grad():
            a = (a - 0.5 * CHAIN["step_size"] * a.grad + CHAIN["step_size"] ** 0.5 * z).clamp(low, high)
    critics.zero_grad(set_to_none=True)
    actor.zero_grad(set_to_none=True)
    with torch.no_grad():
        q = critics(obs, a)
    return q


def bench_chain(batch: int = 256, repeats: int = 9, threads: list[int] | None = None,
                dtypes: list[str] | None = None) -> list[dict]:
    """ms per Langevin chain per form (module docstring), for each task size and thread setting
    (default: 1 thread and torch's default)."""
    dtypes = dtypes or ["float32", "bfloat16"]
    default_threads = torch.get_num_threads()
    thread_settings = threads or sorted({1, default_threads})
    rows = []
    print(f"\nLangevin chain: batch {batch}, T = {CHAIN['steps']}, median of {repeats} (ms per chain); "
          f"CPU capability {torch.backends.cpu.get_cpu_capability()}")
    try:
        for threads in thread_settings:
            torch.set_num_threads(threads)
            for task, (obs_dim, act_dim) in TASK_DIMS.items():
                r = _chain_case(obs_dim, act_dim, batch, repeats, dtypes)
                r.update(task=task, obs_dim=obs_dim, act_dim=act_dim, threads=threads)
                rows.append(r)
                figures = ", ".join(f"{k} {v:.1f}" for k, v in r.items()
                                    if isinstance(v, float) and k not in ("max_diff",))
                print(f"{task} ({obs_dim}/{act_dim}), {threads} thread(s): {figures}; "
                      f"authors/fused {r['authors'] / r['fused']:.2f}x, eager/fused {r['eager'] / r['fused']:.2f}x, "
                      f"max|Δa| fused vs naive {r['max_diff']:.1e}", flush=True)
    finally:
        torch.set_num_threads(default_threads)
    return rows


def _gradient_step_case(obs_dim: int, act_dim: int, steps: int) -> dict:
    """ms per LAC gradient step: RLlib's Learner.update (one call per step, and one call for
    ``steps`` minibatches as LAC's training_step does) vs the same losses in a plain torch loop."""
    import gymnasium as gym
    import numpy as np
    from ray.rllib.core import DEFAULT_MODULE_ID
    from ray.rllib.core.columns import Columns
    from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch

    from lac_rllib.algorithms.lac import module as M
    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.algorithms.lac.learner import critic_targets
    from lac_rllib.constrained.costs import COSTS
    from lac_rllib.constrained.networks import gaussian_kl, gaussian_log_prob

    obs_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
    act_space = gym.spaces.Box(-1.0, 1.0, (act_dim,), np.float32)
    config = LACConfig().training(cost_limit=25.0, lr_schedule="constant")
    learner = config.build_learner(spaces={DEFAULT_MODULE_ID: (obs_space, act_space)})
    rng = np.random.default_rng(0)
    n = 256 * steps
    cols = {Columns.OBS: rng.normal(size=(n, obs_dim)).astype(np.float32),
            Columns.NEXT_OBS: rng.normal(size=(n, obs_dim)).astype(np.float32),
            Columns.ACTIONS: rng.uniform(-1, 1, size=(n, act_dim)).astype(np.float32),
            Columns.REWARDS: rng.normal(size=n).astype(np.float32), COSTS: rng.integers(0, 2, n).astype(np.float32),
            Columns.TERMINATEDS: np.zeros(n, bool), Columns.TRUNCATEDS: np.zeros(n, bool)}

    def rllib(k):
        batch = MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch({c: v[: 256 * k] for c, v in cols.items()})}, 256 * k)
        learner.update(batch=batch, minibatch_size=256, num_total_minibatches=k, timesteps={})

    module = config.get_rl_module_spec(spaces={DEFAULT_MODULE_ID: (obs_space, act_space)}).build()
    module.make_target_networks()
    critic_opt = torch.optim.Adam(module.critics.parameters(), lr=config.critic_lr)
    actor_opt = torch.optim.Adam(module.actor.parameters(), lr=config.actor_lr)
    tensors = {c: torch.as_tensor(v) for c, v in cols.items()}

    def plain(k):
        for i in range(k):
            b = {c: v[256 * i: 256 * (i + 1)] for c, v in tensors.items()}
            out = module._forward_train(b)
            n_r = module.critics.n_reward
            y_r, y_c = critic_targets(b, out[M.Q_TARGET_NEXT], n_r, config)
            q_r, q_c = reward_rows(out[M.Q_PRED], n_r), cost_rows(out[M.Q_PRED], n_r)
            critic_loss = ((q_r - y_r) ** 2).mean(-1).sum() + ((q_c - y_c) ** 2).mean(-1).sum()
            logp = gaussian_log_prob(out[M.ACTOR_TARGET_ACTION], out[M.ACTOR_MEAN], out[M.ACTOR_LOG_STD])
            kl = gaussian_kl(out[M.ACTOR_MEAN], out[M.ACTOR_LOG_STD], out[M.TARGET_MEAN], out[M.TARGET_LOG_STD])
            actor_loss = -logp.mean() + config.beta * kl.mean()
            critic_opt.zero_grad(), actor_opt.zero_grad()
            (critic_loss + actor_loss).backward()
            torch.nn.utils.clip_grad_norm_(module.actor.parameters(), config.actor_grad_clip)
            critic_opt.step(), actor_opt.step()
            with torch.no_grad():
                for main_net, target in module.get_target_network_pairs():
                    for p, tp in zip(main_net.parameters(), target.parameters()):
                        tp.mul_(1 - config.polyak_tau).add_(p, alpha=config.polyak_tau)

    times = _interleaved_median_ms({"plain": lambda: plain(steps), "rllib_batched": lambda: rllib(steps),
                                    "rllib_one_per_call": lambda: rllib(1)}, repeats=3, warmup=1)
    return {"plain": times["plain"] / steps, "rllib_batched": times["rllib_batched"] / steps,
            "rllib_one_per_call": times["rllib_one_per_call"]}


def bench_gradient_step(steps: int = 8, threads: int = 1) -> list[dict]:
    torch.set_num_threads(threads)
    print(f"\nLAC gradient step (batch 256, T = 30, default networks, {threads} thread): ms per step")
    print(f"{'task':<11} {'obs/act':>8} {'plain torch':>12} {'RLlib, 1 call':>14} {'ratio':>7} "
          f"{'RLlib, 1 step/call':>19} {'ratio':>7}")
    rows = []
    for task, (obs_dim, act_dim) in TASK_DIMS.items():
        r = _gradient_step_case(obs_dim, act_dim, steps)
        rows.append({"task": task, **r})
        print(f"{task:<11} {f'{obs_dim}/{act_dim}':>8} {r['plain']:>12.1f} {r['rllib_batched']:>14.1f} "
              f"{r['rllib_batched'] / r['plain']:>6.2f}x {r['rllib_one_per_call']:>19.1f} "
              f"{r['rllib_one_per_call'] / r['plain']:>6.2f}x", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=lambda s: [int(x) for x in s.split(",")], default=None,
                        help="comma-separated torch thread counts (default: 1 and torch's default)")
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--dtypes", type=lambda s: s.split(","), default=["float32", "bfloat16"],
                        help="matmul dtypes of the fused chain and floors (bfloat16 is slow without native bf16)")
    parser.add_argument("--no-gradient-step", action="store_true", help="only the chain table")
    args = parser.parse_args()
    print(f"torch {torch.__version__}, default threads {torch.get_num_threads()}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} "
          "(multi-thread timings collapse when other work holds the cores)")
    bench_chain(repeats=args.repeats, threads=args.threads, dtypes=args.dtypes)
    if not args.no_gradient_step:
        bench_gradient_step()


if __name__ == "__main__":
    main()
