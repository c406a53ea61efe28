"""Record OmniSafe 0.5.0's own SAC-Lag update steps on seeded batches.

Run with OmniSafe's venv (benchmarks/golden/omnisafe_venv.sh; docs/golden.md), from the repository root:

    OMNISAFE_PY benchmarks/golden/omnisafe_sac_lag.py

``SACLag`` is built by ``omnisafe.Agent`` on SafetyPointGoal1-v0 (obs 60, act 2; its task config)
with (16, 16) networks, turned to float64; five of its values are set so that every part of the
step shows above the test's 1e-5: α = 0.2 (the defaults' column; the task's 1e-5 hides the entropy
terms), λ₀ = 0.5 (the task's 0 hides the cost critic in the actor's loss), the multiplier's lr
0.01 and the actor's 1e-3 (the task's 5e-7 and 5e-6 move λ and the actor by less than 1e-5 of
themselves), max_grad_norm 2 (the reward critics' gradient norms, ~2.6, pass it; the cost critic's,
~1, and the actor's, ~0.1, do not: both branches of the clip; at 40 none would). The target
critics start away from the critics (N(0, 0.05²) added: a run's targets lag them), so a target
taken from the wrong network shows.

Then its own ``_update`` (``sac_lag.py``: ``ddpg.py`` ``_update`` with ``update_iters`` = 1, then the
multiplier) is called twice, its replay buffer's ``sample_batch`` answering with the seeded batches:
update 1 (count 1: the reward critics, the cost critic, λ) and update 2 (count 2, a policy-delay
step: the critics, the actor on the stepped critics, Polyak, λ). Past ``warmup_epochs`` (``_epoch``
set beyond it), Jc = ``Metrics/EpCost`` read where the reference reads it (its logger's
``get_stats``). The reparameterised samples (``Normal.rsample``: the next actions of the reward
target, the actor's actions) take their ε from a seeded list, recorded in the order drawn
(``in/eps/<k>``), so the project's learner can be fed the same ε.

Recorded: each update's logged losses and Values, the post-clip gradients of each optimizer's step
(``step<k>/grad/*``), λ after each update, and after update 2 every parameter of the actor, the
critics and their targets. Written to tests/fixtures/golden/sac_lag-omnisafe.npz
(benchmarks/golden/fixture.py)."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402  (the format, shared with the tests' loader)
from omnisafe_first_order import Recorder  # noqa: E402  (logger.store and post-clip gradients)

ROOT = Path(__file__).resolve().parents[2]
ROWS, HIDDEN, EP_COST, SEED, UPDATES = 32, [16, 16], 40.0, 0, 2
OVERRIDES = {"algo_cfgs": {"alpha": 0.2, "max_grad_norm": 2.0}, "model_cfgs": {"actor": {"lr": 1e-3}},
             "lagrange_cfgs": {"lagrangian_multiplier_init": 0.5, "lambda_lr": 0.01}}
#: What its logger stores -> the fixture's names (Value/reward_critic is Q_R1's mean).
LOGGED = {"Loss/Loss_reward_critic": "loss_reward_critic", "Loss/Loss_cost_critic": "loss_cost_critic",
          "Loss/Loss_pi": "loss_pi", "Value/reward_critic": "q_reward_1_mean", "Value/cost_critic": "q_cost_mean"}
NETS = ("actor", "reward_critic", "cost_critic", "target_reward_critic", "target_cost_critic")


def build():
    import omnisafe

    cfgs = {"seed": SEED, "train_cfgs": {"total_steps": 2000, "vector_env_nums": 1, "parallel": 1,
                                         "torch_threads": 1, "device": "cpu"},
            "algo_cfgs": {"steps_per_epoch": 1000, **OVERRIDES["algo_cfgs"]},
            "logger_cfgs": {"use_wandb": False, "use_tensorboard": False, "log_dir": tempfile.mkdtemp()},
            "model_cfgs": {"actor": {"hidden_sizes": HIDDEN, **OVERRIDES["model_cfgs"]["actor"]},
                           "critic": {"hidden_sizes": HIDDEN}},
            "lagrange_cfgs": OVERRIDES["lagrange_cfgs"]}
    agent = omnisafe.Agent("SACLag", "SafetyPointGoal1-v0", custom_cfgs=cfgs).agent
    agent._actor_critic.double()  # noqa: SLF001  parameters keep their identity: the optimizers stay valid
    return agent


def weights(agent) -> dict:
    ac = agent._actor_critic  # noqa: SLF001
    return {f"{net}.{k}": v.detach().clone() for net in NETS for k, v in getattr(ac, net).named_parameters()}


def move_targets(agent, rng: np.random.Generator) -> None:
    """Targets = critics + N(0, 0.05²) per weight."""
    ac = agent._actor_critic  # noqa: SLF001
    with torch.no_grad():
        for net in ("reward_critic", "cost_critic"):
            for p, t in zip(getattr(ac, net).parameters(), getattr(ac, f"target_{net}").parameters()):
                t.copy_(p + torch.as_tensor(rng.normal(scale=0.05, size=tuple(p.shape))))


def make_batch(agent, rng: np.random.Generator) -> dict:
    """obs, next_obs N(0, 1); act U(−1, 1); reward N(0, 3²); cost ∈ {0, 1} (P(1) = 0.3); done
    P(1) = 0.2."""
    obs_dim = agent._env.observation_space.shape[0]  # noqa: SLF001
    act_dim = agent._env.action_space.shape[0]  # noqa: SLF001
    t = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    return {"obs": t(rng.normal(size=(ROWS, obs_dim))), "act": t(rng.uniform(-1, 1, size=(ROWS, act_dim))),
            "reward": t(rng.normal(scale=3.0, size=ROWS)), "cost": t(rng.uniform(size=ROWS) < 0.3),
            "done": t(rng.uniform(size=ROWS) < 0.2), "next_obs": t(rng.normal(size=(ROWS, obs_dim)))}


class RecordedNoise:
    """``Normal.rsample`` with ε taken, in order, from a seeded stream: loc + ε·scale, its own
    formula (torch/distributions/normal.py), ε kept in the order drawn."""

    def __init__(self, rng: np.random.Generator):
        self.rng, self.drawn = rng, []

    def __enter__(self):
        self._rsample = Normal.rsample

        def rsample(dist, sample_shape=torch.Size()):  # noqa: B008
            shape = dist._extended_shape(sample_shape)  # noqa: SLF001
            eps = torch.as_tensor(self.rng.normal(size=tuple(shape)), dtype=dist.loc.dtype)
            self.drawn.append(eps.clone())
            return dist.loc + eps * dist.scale

        Normal.rsample = rsample
        return self

    def __exit__(self, *exc):
        Normal.rsample = self._rsample


def step(agent, batches: list[dict], ep_cost: float, noise: RecordedNoise) -> dict:
    """The reference's own ``_update``, once per batch."""
    ac = agent._actor_critic  # noqa: SLF001
    agent._logger.get_stats = lambda key, *_: (ep_cost, 0.0, 0.0, 0.0) if key == "Metrics/EpCost" else None  # noqa: SLF001
    agent._epoch = agent._cfgs.algo_cfgs.warmup_epochs + 1  # noqa: SLF001  λ steps past the warm-up
    assert agent._cfgs.algo_cfgs.update_iters == 1 and agent._update_count == 0  # noqa: SLF001
    out = {}
    for k, batch in enumerate(batches, 1):
        rec = Recorder(agent)
        agent._buf.sample_batch = lambda b=batch: b  # noqa: SLF001
        drawn = len(noise.drawn)
        agent._update()  # noqa: SLF001
        out[f"step{k}/noise_draws"] = len(noise.drawn) - drawn
        out[f"step{k}/nu"] = agent._lagrange.lagrangian_multiplier.item()  # noqa: SLF001
        for key, name in LOGGED.items():
            if key in rec.logged:
                out[f"step{k}/{name}"] = rec.logged[key]
        out.update({f"step{k}/grad/{n}": g for n, g in rec.grads.items()})
    out.update({f"after/{k}": v for k, v in weights(agent).items()})
    assert ac.actor_optimizer.state, "the actor took no step"
    return out


def record(out_dir: Path) -> Path:
    import omnisafe

    torch.manual_seed(SEED)
    agent = build()
    rng = np.random.default_rng(SEED)
    move_targets(agent, rng)
    before = weights(agent)
    batches = [make_batch(agent, rng) for _ in range(UPDATES)]
    with RecordedNoise(np.random.default_rng(SEED + 1)) as noise:
        outputs = step(agent, batches, EP_COST, noise)
    cfgs = agent._cfgs  # noqa: SLF001
    meta = {"reference": "OmniSafe", "reference_version": omnisafe.__version__,
            "reference_source": "PyPI omnisafe==0.5.0 (its installed algorithms/off_policy/{sac_lag,sac,ddpg}.py)",
            "algorithm": "sac_lag", "omnisafe_class": "SACLag", "task": "SafetyPointGoal1-v0",
            "hidden": HIDDEN, "rows": ROWS, "updates": UPDATES, "torch": torch.__version__,
            "command": "OMNISAFE_PY benchmarks/golden/omnisafe_sac_lag.py", "overrides": OVERRIDES,
            "alpha_used": agent._alpha,  # noqa: SLF001  exp(log α) in float32, as its losses read it
            "algo_cfgs": {k: v for k, v in cfgs.algo_cfgs.todict().items() if not isinstance(v, dict)},
            "lagrange_cfgs": cfgs.lagrange_cfgs.todict(),
            "lr": cfgs.model_cfgs.actor.lr, "critic_lr": cfgs.model_cfgs.critic.lr,
            "noise_order": "step1: the reward target's a' ~ π(·|s'); step2: the same, then the actor's ã ~ π(·|s)"}
    inputs = {f"step{k}/{name}": v for k, b in enumerate(batches, 1) for name, v in b.items()}
    inputs.update({f"eps/{i}": e for i, e in enumerate(noise.drawn)})
    inputs.update({"ep_cost": EP_COST, "nu_before": float(cfgs.lagrange_cfgs.lagrangian_multiplier_init)})
    return fixture.save(out_dir / "sac_lag-omnisafe.npz", meta, inputs, before, outputs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "fixtures" / "golden")
    args = parser.parse_args()
    os.environ.setdefault("WANDB_MODE", "disabled")
    record(args.out)


if __name__ == "__main__":
    main()
