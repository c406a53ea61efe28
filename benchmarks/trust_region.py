"""The trust-region step's parts against one plain gradient, on the same whole batch.

    python benchmarks/trust_region.py [--task SafetyPointGoal1-v0] [--rows 20000] [--repeats 5]

TRPO-Lag's, CPO's and PCPO's policy takes one step per iteration on the whole batch
(lac_rllib/algorithms/trpo_lag/learner.py): a gradient of the surrogate, the first-order graph of
the mean KL (``fisher_vector_product``, built once), ``cg_iters`` Fisher-vector products (one
backward each, double backward), one more for q = xᵀHx, and the line search's evaluations; CPO
and PCPO add a gradient and a second solve. This times each part at the task's preset networks on
a batch of ``--rows`` real rows plus 1% phantom rows (OmniSafe's 20k-step iteration on
PointGoal1 by default), the policy of a TRPO-Lag learner built for the task, synthetic
observations, actions drawn from the policy, standard-normal advantages: ms per call, median over
interleaved repeats, one torch thread, and each part's cost in plain gradients. Also the whole
step (TRPO-Lag's ``policy_step``: an accepted step costs one line-search evaluation). The CPU
(lscpu's model name) is printed with the figures. No asserts: figures only.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import time

import torch


def cpu_name() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return next((line.split(":", 1)[1].strip() for line in out.splitlines() if line.startswith("Model name")),
                "unknown")


def median_ms(fns: dict, repeats: int) -> dict:
    """Median ms per call of each function, the candidates alternating (load hits them alike)."""
    times = {name: [] for name in fns}
    for _ in range(repeats + 1):  # the first round warms up
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append((time.perf_counter() - t0) * 1e3)
    return {name: statistics.median(ts[1:]) for name, ts in times.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="SafetyPointGoal1-v0")
    parser.add_argument("--rows", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    from ray.rllib.core import DEFAULT_MODULE_ID
    from ray.rllib.core.columns import Columns
    from ray.rllib.evaluation.postprocessing import Postprocessing

    from lac_rllib.algorithms.trpo_lag.config import TRPOLagConfig
    from lac_rllib.algorithms.trpo_lag.learner import COST_ADVANTAGES, PolicyOnBatch
    from lac_rllib.families.trust_region.step import conjugate_gradient, fisher_vector_product, flat_grad
    from lac_rllib.tasks import get_task

    torch.set_num_threads(1)
    spec = get_task(args.task)
    config = TRPOLagConfig().task(args.task).training(total_env_steps=10**7, torch_threads=1)
    learner = config.build_learner(env=spec.make())
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    gen = torch.Generator().manual_seed(0)
    n = args.rows + max(1, args.rows // 100)
    obs = torch.randn(n, spec.obs_dim, generator=gen)
    with torch.no_grad():
        dist = module.get_train_action_dist_cls().from_logits(module.action_dist_inputs(obs))
        actions = dist.sample()
        logp = dist.logp(actions)
    mask = torch.ones(n, dtype=torch.bool)
    mask[args.rows:] = False
    whole = {Columns.OBS: obs, Columns.ACTIONS: actions, Columns.ACTION_LOGP: logp, Columns.LOSS_MASK: mask,
             Postprocessing.ADVANTAGES: torch.randn(n, generator=gen), COST_ADVANTAGES: torch.randn(n, generator=gen)}
    policy = PolicyOnBatch(module, whole)
    adv = whole[Postprocessing.ADVANTAGES]
    g = flat_grad(policy.surrogate(adv), policy.params)
    fvp = fisher_vector_product(policy.mean_kl, policy.params, config.cg_damping)
    theta = [p.detach().clone() for p in policy.params]

    def whole_step():
        learner.policy_step(DEFAULT_MODULE_ID, config, module, PolicyOnBatch(module, whole))
        with torch.no_grad():  # back to θ_old, so every repeat steps from the same point
            for p, t in zip(policy.params, theta):
                p.copy_(t)

    ms = median_ms({
        "gradient of the surrogate (forward + backward)": lambda: flat_grad(policy.surrogate(adv), policy.params),
        "mean KL's first-order graph (once per step)": lambda: fisher_vector_product(policy.mean_kl, policy.params,
                                                                                       config.cg_damping),
        "one Fisher-vector product": lambda: fvp(g),
        f"conjugate gradient, {config.cg_iters} products": lambda: conjugate_gradient(fvp, g, config.cg_iters),
        "line-search evaluation (loss and KL, no grad)": lambda: torch.no_grad()(
            lambda: (policy.surrogate(adv), policy.mean_kl()))(),
    }, args.repeats)
    # Last and apart: it moves the parameters (restored after), which ends the product's graph above.
    ms |= median_ms({"TRPO-Lag's whole policy step": whole_step}, args.repeats)
    base = next(iter(ms.values()))
    params = sum(p.numel() for p in policy.params)
    print(f"{args.task}: {args.rows} real rows + {n - args.rows} phantom, policy {config.hidden} {config.activation} "
          f"({params} parameters), one torch thread; CPU: {cpu_name()}\n")
    print("| part | ms | in gradients |\n|---|---:|---:|")
    for name, t in ms.items():
        print(f"| {name} | {t:.1f} | {t / base:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
