"""Plain-torch gradient steps of the baselines: the same networks, losses and optimizers as the
project's learners, with no RLlib in the loop. ``benchmarks/update_step.py`` times them beside the
learners' steps, so each ratio is read against the maths alone; tests/benchmarks/test_update_step.py
checks that each computes the learner's loss and gradients on one batch (1e-6), i.e. that it
measures the same work.

- :class:`PPOLagStep`: OmniSafe's PPO-Lag minibatch step (PPO's clipped surrogate on
  A = (A_R − ν·A_C)/(1 + ν), both critics' MSE over the real rows, the critics' L2), copies of the
  module's three MLPs and free log σ, one torch Adam and one global-norm clip per network;
- :class:`SACLagStep`: SAC-Lag's step in OmniSafe's order (the critics on their targets, then on a
  policy-delay step the actor on the stepped critics and Polyak), on a copy of the module's own
  torch networks (its ensembles and actor: plain torch already, the critics in the module's
  ``critic_dtype``), fused Adam as the learner's.

:func:`matmul_seconds` is a step's floor: the time spent inside its matrix products (torch's
profiler, self time of ``mm``/``addmm``/``bmm``/``baddbmm``).
"""

from __future__ import annotations

import copy

import torch


def _mlp(*parts) -> torch.nn.Sequential:
    """RLlib's TorchMLP wrappers (``.net.mlp``) unwrapped into one Sequential, deep-copied."""
    return torch.nn.Sequential(*(copy.deepcopy(p.net.mlp) for p in parts))


class PPOLagStep:
    @staticmethod
    def warmup_iterations(steps: int) -> int:
        return 1

    def __init__(self, module, config):
        self.actor = _mlp(module.encoder.actor_encoder, module.pi)
        self.log_std = copy.deepcopy(module.pi.log_std)
        self.critic = _mlp(module.encoder.critic_encoder, module.vf)
        self.cost_critic = _mlp(module.cost_vf.encoder, module.cost_vf.head)
        self.nu = float(module.nu)
        self.config, self.minibatch_rows = config, config.minibatch_size
        lr = float(config.lr)  # the decay's start: a constant rate costs the same
        self.networks = {"policy": [*self.actor.parameters(), self.log_std],
                         "critic": list(self.critic.parameters()), "cost_critic": list(self.cost_critic.parameters())}
        self.optimizers = [torch.optim.Adam(ps, lr=lr if name == "policy" else config.critic_lr)
                           for name, ps in self.networks.items()]

    def loss(self, b: dict) -> torch.Tensor:
        cfg, nu, mask = self.config, self.nu, b["loss_mask"]
        mean = self.actor(b["obs"])
        dist = torch.distributions.Normal(mean, self.log_std.expand_as(mean).exp())
        ratio = torch.exp(dist.log_prob(b["actions"]).sum(-1) - b["action_logp"])
        adv = (b["advantages"] - nu * b["cost_advantages"]) / (1.0 + nu)
        surrogate = torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - cfg.clip_param, 1 + cfg.clip_param))
        vf = torch.pow(self.critic(b["obs"]).squeeze(-1) - b["value_targets"], 2.0)
        loss = torch.sum((-surrogate + cfg.vf_loss_coeff * vf)[mask]) / torch.sum(mask)
        cost_vf = ((self.cost_critic(b["obs"]).squeeze(-1) - b["cost_value_targets"]) ** 2)[mask].mean()
        loss = loss + cfg.vf_loss_coeff * cost_vf
        if cfg.critic_l2:
            critics = [*self.networks["critic"], *self.networks["cost_critic"]]
            loss = loss + cfg.critic_l2 * sum((p**2).sum() for p in critics)
        return loss

    def step(self, b: dict) -> None:
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)
        self.loss(b).backward()
        if self.config.grad_clip:
            for params in self.networks.values():
                torch.nn.utils.clip_grad_norm_(params, self.config.grad_clip)
        for opt in self.optimizers:
            opt.step()


class SACLagStep:
    @staticmethod
    def warmup_iterations(steps: int) -> int:
        return 2000 // steps + 1  # past benchmark_fields' 2,000 random steps

    def __init__(self, module, config):
        from lac_rllib.algorithms.sac_lag.learner import actor_loss, critic_targets  # plain functions
        from lac_rllib.algorithms.sac_lag.networks import squash

        self.m = copy.deepcopy(module)
        self.config, self.updates, self.minibatch_rows = config, 0, config.batch_size
        self.critic_targets, self.actor_loss, self.squash = critic_targets, actor_loss, squash
        self.critics = [list(self.m.reward_critics.parameters()), list(self.m.cost_critic.parameters())]
        self.critic_optimizers = [torch.optim.Adam(ps, lr=config.critic_lr, fused=True) for ps in self.critics]
        self.actor_optimizer = torch.optim.Adam(self.m.actor.parameters(), lr=config.actor_lr, fused=True)

    def critic_loss(self, b: dict) -> torch.Tensor:
        obs, act, next_obs = b["obs"], b["actions"], b["new_obs"]
        with torch.no_grad():
            mean, log_std = self.m.actor(next_obs)
            next_act, logp_next = self.m._sample(mean, log_std)
            next_det = self.squash(mean, self.m.action_low, self.m.action_high)
            out = {"q_reward_next": self.m.target_reward_critics(next_obs, next_act), "logp_next": logp_next,
                   "q_cost_next": self.m.target_cost_critic(next_obs, next_det)[0]}
        q_r, q_c = self.m.reward_critics(obs, act), self.m.cost_critic(obs, act)[0]
        y_r, y_c = self.critic_targets(b, out, self.config)
        return ((q_r - y_r) ** 2).mean(-1).sum() + ((q_c - y_c) ** 2).mean()

    def step(self, b: dict) -> None:
        for opt in self.critic_optimizers:
            opt.zero_grad(set_to_none=True)
        self.critic_loss(b).backward()
        for params, opt in zip(self.critics, self.critic_optimizers):
            torch.nn.utils.clip_grad_norm_(params, self.config.max_grad_norm)
            opt.step()
        self.updates += 1
        if self.updates % self.config.policy_delay == 0:
            self.actor_optimizer.zero_grad(set_to_none=True)
            self.actor_loss(self.m.forward_actor(b["obs"]), self.m.nu, self.config.alpha).backward()
            torch.nn.utils.clip_grad_norm_(self.m.actor.parameters(), self.config.max_grad_norm)
            self.actor_optimizer.step()
            with torch.no_grad():
                for main, target in self.m.get_target_network_pairs():
                    for p, t in zip(main.parameters(), target.parameters()):
                        t.lerp_(p, self.config.polyak_tau)


#: algo → its plain-torch step.
STEPS = {"ppo_lag": PPOLagStep, "sac_lag": SACLagStep}


def make_batch(algo: str, module, rows: int, seed: int = 0) -> dict:
    """A minibatch of ``rows`` rows for ``algo``'s step, shaped as its learner's (random values;
    PPO-Lag's log-probabilities the current policy's, so its ratios start at 1; a few rows
    masked out, as RLlib's phantom rows are)."""
    gen = torch.Generator().manual_seed(seed)
    obs_dim, act_dim = module.observation_space.shape[0], module.action_space.shape[0]
    obs = torch.randn(rows, obs_dim, generator=gen)
    actions = torch.rand(rows, act_dim, generator=gen) * 2 - 1
    if STEPS[algo] is PPOLagStep:
        with torch.no_grad():
            logits = module.action_dist_inputs(obs)
            dist = module.get_train_action_dist_cls().from_logits(logits)
        mask = torch.ones(rows, dtype=torch.bool)
        mask[::16] = False
        return {"obs": obs, "actions": actions, "action_logp": dist.logp(actions), "action_dist_inputs": logits,
                "loss_mask": mask, "advantages": torch.randn(rows, generator=gen),
                "value_targets": torch.randn(rows, generator=gen), "cost_advantages": torch.randn(rows, generator=gen),
                "cost_value_targets": torch.randn(rows, generator=gen)}
    return {"obs": obs, "actions": actions, "new_obs": obs + 0.1 * torch.randn(rows, obs_dim, generator=gen),
            "rewards": torch.randn(rows, generator=gen), "costs": (torch.rand(rows, generator=gen) < 0.1).float(),
            "terminateds": torch.zeros(rows, dtype=torch.bool)}


def matmul_seconds(step, batches: list[dict]) -> float:
    """Seconds per step spent inside matrix products over ``batches`` (torch's profiler)."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for b in batches:
            step(b)
    kernels = ("aten::mm", "aten::addmm", "aten::bmm", "aten::baddbmm")
    micros = sum(e.self_cpu_time_total for e in prof.key_averages() if e.key in kernels)
    return micros * 1e-6 / len(batches)
