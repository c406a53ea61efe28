"""Record OmniSafe 0.5.0's own update step of PPO-Lag, FOCOPS, CUP and P3O on one seeded batch.

Run with OmniSafe's venv (benchmarks/golden/omnisafe_venv.sh; docs/golden.md), from the repository root:

    OMNISAFE_PY benchmarks/golden/omnisafe_first_order.py --algos ppo_lag,focops,cup,p3o

Each algorithm's object is built by ``omnisafe.Agent`` on SafetyPointGoal1-v0 (obs 60, act 2) with
(16, 16) networks (small fixtures; the step's arithmetic does not depend on the width), turned to
float64; then its own methods take one step, as its ``_update`` calls them for one minibatch:
the multiplier's ``update_lagrange_multiplier(Jc)`` (Jc = EpCost, read where the reference reads it:
its logger's ``get_stats``), ``_update_reward_critic``, ``_update_cost_critic``, ``_update_actor``
(FOCOPS with ``_p_dist``, the policy at the update's start, set to the batch's behaviour policy, as
its ``_update`` does per minibatch); CUP then its second stage's step (``_loss_pi_cost`` on
``_p_dist``, the clip and Adam step of its ``_update``). The behaviour policy is the starting policy
moved by noise, so ratios leave the clip range and some rows leave FOCOPS's and CUP's trust region.
Written to tests/fixtures/golden/<algo>-omnisafe.npz (benchmarks/golden/fixture.py)."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402  (the format, shared with the tests' loader)

OMNISAFE_NAMES = {"ppo_lag": "PPOLag", "focops": "FOCOPS", "cup": "CUP", "p3o": "P3O"}
ROWS, HIDDEN, EP_COST, SEED = 64, [16, 16], 40.0, 0


def build(algo: str):
    import omnisafe

    cfgs = {"seed": SEED, "train_cfgs": {"total_steps": 2000, "vector_env_nums": 1, "parallel": 1,
                                         "torch_threads": 1, "device": "cpu"},
            "algo_cfgs": {"steps_per_epoch": 1000},
            "logger_cfgs": {"use_wandb": False, "use_tensorboard": False, "log_dir": tempfile.mkdtemp()},
            "model_cfgs": {"actor": {"hidden_sizes": HIDDEN}, "critic": {"hidden_sizes": HIDDEN}}}
    agent = omnisafe.Agent(OMNISAFE_NAMES[algo], "SafetyPointGoal1-v0", custom_cfgs=cfgs).agent
    agent._actor_critic.double()  # noqa: SLF001  parameters keep their identity: the optimizers stay valid
    return agent


class Recorder:
    """What the reference logs (its ``logger.store``) and each optimizer's gradients at its step
    (after the clip: what Adam consumes), keyed by the actor-critic's parameter names."""

    def __init__(self, agent):
        self.logged, self.grads = {}, {}
        ac = agent._actor_critic  # noqa: SLF001
        names = {id(p): n for n, p in ac.named_parameters()}
        agent._logger.store = lambda data, **_: self.logged.update(  # noqa: SLF001
            {k: float(v.mean()) if torch.is_tensor(v) else float(v) for k, v in data.items()})
        for optim in (ac.actor_optimizer, ac.reward_critic_optimizer, ac.cost_critic_optimizer):
            self._wrap(optim, names)

    def _wrap(self, optim, names):
        step = optim.step

        def recording_step(*args, **kwargs):
            for group in optim.param_groups:
                for p in group["params"]:
                    key = names[id(p)]
                    self.grads[key if key not in self.grads else f"{key}#2"] = p.grad.detach().clone()
            return step(*args, **kwargs)

        optim.step = recording_step


def make_batch(agent, rng: np.random.Generator) -> dict:
    """Observations N(0, 1); actions from a behaviour policy = the starting policy with its mean
    moved by N(0, 0.15²) and log σ by N(0, 0.1²) per row; logp the behaviour policy's; advantages
    and value targets N(0, 1) (targets offset from the critics' outputs)."""
    obs_dim = agent._env.observation_space.shape[0]  # noqa: SLF001
    act_dim = agent._env.action_space.shape[0]  # noqa: SLF001
    obs = torch.as_tensor(rng.normal(size=(ROWS, obs_dim)))
    with torch.no_grad():
        dist = agent._actor_critic.actor(obs)  # noqa: SLF001
        old_mean = dist.mean + torch.as_tensor(rng.normal(scale=0.15, size=(ROWS, act_dim)))
        old_log_std = dist.stddev.log() + torch.as_tensor(rng.normal(scale=0.1, size=(ROWS, act_dim)))
        behaviour = Normal(old_mean, old_log_std.exp())
        act = behaviour.mean + behaviour.stddev * torch.as_tensor(rng.normal(size=(ROWS, act_dim)))
        logp = behaviour.log_prob(act).sum(-1)
    return {"obs": obs, "act": act, "logp": logp, "old_mean": old_mean, "old_log_std": old_log_std,
            "adv_r": torch.as_tensor(rng.normal(size=ROWS)), "adv_c": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_r": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_c": torch.as_tensor(rng.normal(loc=2.0, size=ROWS))}


def step(algo: str, agent, batch: dict, ep_cost: float) -> dict:
    """The reference's own methods, in its ``_update``'s order for one minibatch."""
    ac, cfgs = agent._actor_critic, agent._cfgs  # noqa: SLF001
    agent._logger.get_stats = lambda key, *_: (ep_cost, 0.0, 0.0, 0.0) if key == "Metrics/EpCost" else None  # noqa: SLF001
    rec = Recorder(agent)
    out = {}
    if hasattr(agent, "_lagrange"):
        agent._lagrange.update_lagrange_multiplier(ep_cost)  # noqa: SLF001
        out["nu"] = float(agent._lagrange.lagrangian_multiplier)  # noqa: SLF001
    b = batch
    agent._update_reward_critic(b["obs"], b["target_value_r"])  # noqa: SLF001
    agent._update_cost_critic(b["obs"], b["target_value_c"])  # noqa: SLF001
    if algo == "focops":
        agent._p_dist = Normal(b["old_mean"], b["old_log_std"].exp())  # noqa: SLF001
    agent._update_actor(b["obs"], b["act"], b["logp"], b["adv_r"], b["adv_c"])  # noqa: SLF001
    out.update({"loss_pi": rec.logged["Loss/Loss_pi"], "loss_reward_critic": rec.logged["Loss/Loss_reward_critic"],
                "loss_cost_critic": rec.logged["Loss/Loss_cost_critic"]})
    if algo == "p3o":
        out["loss_pi_cost"] = rec.logged["Loss/Loss_pi_cost"]
    out.update({f"grad/{k}": v for k, v in rec.grads.items()})
    out.update({f"after/{k}": v.detach().clone() for k, v in ac.state_dict().items()})
    if algo == "cup":  # the second stage, one minibatch: its _update's loop body
        agent._p_dist = Normal(b["old_mean"], b["old_log_std"].exp())  # noqa: SLF001
        rec.grads.clear()
        loss_cost = agent._loss_pi_cost(b["obs"], b["act"], b["logp"], b["adv_c"])  # noqa: SLF001
        ac.actor_optimizer.zero_grad()
        loss_cost.backward()
        if cfgs.algo_cfgs.max_grad_norm is not None:
            torch.nn.utils.clip_grad_norm_(ac.actor.parameters(), cfgs.algo_cfgs.max_grad_norm)
        ac.actor_optimizer.step()
        out["stage2/loss_pi_c"] = rec.logged["Loss/Loss_pi_c"]
        out.update({f"stage2/grad/{k}": v for k, v in rec.grads.items()})
        out.update({f"stage2/after/{k}": v.detach().clone() for k, v in ac.actor.state_dict().items()})
    return out


def record(algo: str, out_dir: Path) -> Path:
    import omnisafe

    torch.manual_seed(SEED)
    agent = build(algo)
    before = {k: v.detach().clone() for k, v in agent._actor_critic.state_dict().items()}  # noqa: SLF001
    batch = make_batch(agent, np.random.default_rng(SEED))
    outputs = step(algo, agent, batch, EP_COST)
    cfgs = agent._cfgs  # noqa: SLF001
    meta = {"reference": "OmniSafe", "reference_version": omnisafe.__version__,
            "reference_source": "PyPI omnisafe==0.5.0 (its installed algorithms/on_policy/*.py)",
            "algorithm": algo, "omnisafe_class": OMNISAFE_NAMES[algo], "task": "SafetyPointGoal1-v0",
            "hidden": HIDDEN, "rows": ROWS, "torch": torch.__version__,
            "command": "OMNISAFE_PY benchmarks/golden/omnisafe_first_order.py --algos " + algo,
            "algo_cfgs": {k: v for k, v in cfgs.algo_cfgs.todict().items() if not isinstance(v, dict)},
            "lagrange_cfgs": cfgs.lagrange_cfgs.todict() if "lagrange_cfgs" in cfgs else None,
            "lr": cfgs.model_cfgs.actor.lr, "critic_lr": cfgs.model_cfgs.critic.lr}
    inputs = {**batch, "ep_cost": EP_COST}
    if "nu" in outputs:
        inputs["nu_before"] = float(cfgs.lagrange_cfgs.lagrangian_multiplier_init)
    return fixture.save(out_dir / f"{algo}-omnisafe.npz", meta, inputs, before, outputs)


def main() -> None:
    fixture.run_for_algos(__doc__, OMNISAFE_NAMES, record)


if __name__ == "__main__":
    main()
