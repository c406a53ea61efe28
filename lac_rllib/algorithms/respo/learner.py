"""RESPOTorchLearner: PPO-Lag's learner with RESPO's policy loss, its reach critic and ν's step.
Source tag: [G] Ganai et al.'s respo.py (``compute_loss_pi``, ``compute_loss_v``, ``update``).

One iteration (one ``learner_group.update``), with ψ(s) = 1 − V_p(s) from V_p at collection
(reachability.py) and b = ``multiplier_cost_limit`` (None: the run's cost limit; [G]: 0):

1. ν = softplus(p) takes one Adam step on the loss −p·(J_C − b)·mean_batch(ψ) [G update:
   ``loss_penalty = -penalty_param*cost_dev``], J_C the mean cost of this iteration's completed
   episodes. RLlib calls ``before_gradient_based_update`` before the learner connector has built
   the batch, so J_C is taken there and the step at the first loss call of the update, before any
   gradient step: once per iteration;
2. each minibatch, with r = π(a|s)/π_old(a|s), A^R standardised and A^C centred (cost_gae.py):

       L_π = −[ min(r·A^R·ψ, clip(r, 1 ± ε)·A^R·ψ) − r·A^C·(ν·ψ + (1 − ψ)) ] / (1 + ν)

   averaged over the real rows [G compute_loss_pi: loss_rpi − loss_cpi, over 1 + penalty], plus
   the MSE of V_R, V_C (PPO-Lag's) and V_p against its targets p_t [G compute_loss_v], each network
   with its own Adam; V_p's at ``reach_critic_lr`` with no L2 [G pvf_optimizer];
3. PPO-Lag's KL stop: before each epoch, on the whole batch [G: before each of its 80 steps]; the
   critics take every epoch's steps (``kl_stop_critics=False`` [G]).

Every lr, ν's included, decays linearly to 0 with the policy's (``decay_every_lr`` [G LinearLR on
all five optimizers]): ν's is lagrangian_lr times the policy's current lr over its initial one.

With K constraints: a reach critic V_pk, ψ_k = 1 − V_pk and a ν_k per constraint, each ν_k stepping
on (J_Ck − b_k)·mean(ψ_k); the loss

    L_π = −[ min(r·A^R·ψ, clip(r, 1 ± ε)·A^R·ψ) − Σ_k r·A^C_k·(ν_k·ψ_k + (1 − ψ_k)) ] / (1 + Σ_k ν_k),

ψ = Π_k ψ_k: the reward is pursued where no constraint's violation is reachable (the K
reachabilities taken as independent; [G] states one constraint).
"""

from __future__ import annotations

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.algorithms.respo.config import REACH_PROB_MEAN, REACH_VF_LOSS
from lac_rllib.algorithms.respo.reachability import REACH_PROBS, REACH_TARGETS, ReachTargets
from lac_rllib.constrained.lagrange import LagrangeMultiplier, Multipliers, each_multiplier, nu_total
from lac_rllib.constrained.metrics import NU, per_constraint
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.learner import COST_CRITIC, CRITIC, POLICY, cost_critic_loss

REACH_CRITIC = "reach_critic"  # the 4th optimizer's name


class ReachWeightedMultiplier(LagrangeMultiplier):
    """ν of RESPO. ``step(J_C)``, PPO-Lag's call before the update, only records J_C;
    ``step_weighted(ψ̄)`` then makes the rule's step on the error (J_C − b)·ψ̄ [G cost_deviation],
    ψ̄ = mean(1 − V_p) over the batch, and projects as :class:`LagrangeMultiplier` does."""

    pending: float | None = None

    def step(self, episode_cost: float | None) -> float:
        self.pending = episode_cost
        return self.value

    def step_weighted(self, safe_fraction: float) -> float:
        j_c, self.pending = self.pending, None
        if j_c is None:  # no episode completed this iteration: no step
            return self.value
        nu = max(0.0, self.rule.step(self.value, (j_c - self.cost_limit) * safe_fraction, 0.0))
        upper = self.upper
        self._value.fill_(min(nu, upper) if upper is not None else nu)
        return self.value


def set_rule_lr(rule, lr: float) -> None:
    """The learning rate of a step rule: AdamStep and GradientStep have ``lr``, SoftplusAdamStep an
    ``adam`` that has (constrained/lagrange.py)."""
    getattr(rule, "adam", rule).lr = float(lr)


class RESPOTorchLearner(PPOLagTorchLearner):
    RLLIB_LOSS = False
    MINIBATCH_COLUMNS = (*PPOLagTorchLearner.MINIBATCH_COLUMNS, REACH_PROBS, REACH_TARGETS)

    @override(PPOLagTorchLearner)
    def build(self) -> None:
        self.reachability = ReachTargets(gamma=self.config.reach_gamma)
        super().build()
        self.nu_due: set[str] = set()

    @override(PPOLagTorchLearner)
    def learner_pieces(self) -> list:
        """PPO-Lag's, then the reach targets, after the cost GAE: the phantom rows' costs are 0 there."""
        return [*super().learner_pieces(), ("append", self.reachability)]

    @override(PPOLagTorchLearner)
    def make_multiplier(self, module_id, module) -> LagrangeMultiplier | Multipliers:
        """PPO-Lag's rule and bound (softplus-Adam by default [G]), on the weighted error and b (with
        K constraints each ν_k on its own, b_k its limit unless ``multiplier_cost_limit`` is set)."""
        base, config = super().make_multiplier(module_id, module), self.config.get_config_for_module(module_id)

        def weighted(part: LagrangeMultiplier, value, limit: float) -> ReachWeightedMultiplier:
            return ReachWeightedMultiplier(value, cost_limit=limit, rule=part.rule, bound=part.bound,
                                           bounded=part.bounded)

        if not isinstance(base, Multipliers):
            return weighted(base, module.unwrapped().nu, config.multiplier_limit)
        fixed = config.multiplier_cost_limit
        limits = [fixed if fixed is not None else b for b in config.constraint_set.limits]
        base.parts = [weighted(part, module.unwrapped().nu[k], limit)
                      for k, (part, limit) in enumerate(zip(base.parts, limits))]
        return base

    @override(PPOLagTorchLearner)
    def optimizer_groups(self, module, config) -> dict:
        """PPO-Lag's networks, the critics' lr decaying with the policy's (``decay_every_lr`` [G]),
        and V_p's Adam at ``reach_critic_lr`` [G pvf_optimizer]."""
        groups = super().optimizer_groups(module, config)
        for name in (CRITIC, COST_CRITIC):
            parts, lr = groups[name]
            groups[name] = (parts, config.lr_or_schedule(lr))
        return {**groups, REACH_CRITIC: ([module.reach_vf], config.lr_or_schedule(config.reach_critic_lr))}

    # ----- ν: J_C before the update, its step at the update's first loss call -----
    @override(PPOLagTorchLearner)
    def before_gradient_based_update(self, *, timesteps) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # records J_C in each multiplier
        self.nu_due = set(self.multipliers)

    @override(PPOLagTorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        if module_id in self.nu_due:  # the update's first minibatch: before any gradient step
            self.nu_due.discard(module_id)
            self.step_nu(module_id, config)
        return super().compute_loss_for_module(module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)

    def step_nu(self, module_id, config) -> None:
        """ν's one step of the iteration on (J_C − b)·mean(1 − V_p) [G update], at the decayed lr."""
        multiplier = self.multipliers[module_id]
        decay = 1.0
        if config.decay_every_lr and config.policy_lr_schedule == "linear":
            decay = self._get_optimizer_lr(self.get_optimizer(module_id, POLICY)) / config.lr
        safe = self.reachability.safe_fraction[module_id]
        if not isinstance(multiplier, Multipliers):
            set_rule_lr(multiplier.rule, config.lagrangian_lr * decay)
            multiplier.step_weighted(safe)
            self.metrics.log_dict({NU: multiplier.value, REACH_PROB_MEAN: 1.0 - safe}, key=module_id, window=1)
            return
        names = config.constraint_set.names
        for part, safe_k in zip(each_multiplier(multiplier), safe, strict=True):  # each ν_k on its own ψ̄_k
            set_rule_lr(part.rule, config.lagrangian_lr * decay)
            part.step_weighted(safe_k)
        self.metrics.log_dict({NU: max(multiplier.value), REACH_PROB_MEAN: 1.0 - min(safe),
                               **{per_constraint(NU, n): v for n, v in zip(names, multiplier.value)},
                               **{per_constraint(REACH_PROB_MEAN, n): 1.0 - f for n, f in zip(names, safe)}},
                              key=module_id, window=1)

    # ----- losses -----
    @override(PPOLagTorchLearner)
    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """A^R alone: the loss weighs it and A^C itself (:meth:`policy_loss`)."""
        return batch[Postprocessing.ADVANTAGES]

    @override(PPOLagTorchLearner)
    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """L_π per row (the module docstring) [G compute_loss_pi]."""
        nu = module.nu.detach()
        psi = 1.0 - batch[REACH_PROBS] if config.reach_weighted else 1.0  # ψ = 1 − V_p(s), at collection
        ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])
        clipped = torch.clamp(ratio, 1 - config.clip_param, 1 + config.clip_param)
        if nu.dim() == 1:  # K constraints (the module docstring): ψ_k per constraint, their product for A^R
            psi_k = psi if torch.is_tensor(psi) else torch.ones_like(nu)
            psi = psi_k.prod(-1) if torch.is_tensor(psi) else 1.0
            reward = torch.min(ratio * advantages * psi, clipped * advantages * psi)
            cost = (ratio[:, None] * batch[COST_ADVANTAGES] * (nu * psi_k + (1.0 - psi_k))).sum(-1)
            return -(reward - cost) / (1.0 + nu_total(nu)), None
        reward = torch.min(ratio * advantages * psi, clipped * advantages * psi)  # [G loss_rpi]
        cost = ratio * batch[COST_ADVANTAGES] * (nu * psi + (1.0 - psi))  # [G loss_cpi], unclipped
        return -(reward - cost) / (1.0 + nu), None

    @override(PPOLagTorchLearner)
    def fused_loss(self, module_id, config, module, batch, fwd_out, advantages) -> torch.Tensor:
        """PPO-Lag's loss (the policy's above, V_R's and V_C's MSE) plus V_p's MSE [G compute_loss_v]."""
        loss = super().fused_loss(module_id, config, module, batch, fwd_out, advantages)
        mask = batch[Columns.LOSS_MASK]
        reach_loss = cost_critic_loss(module.compute_reach_probs(batch), batch[REACH_TARGETS], mask)  # Σ_k with K
        if self.reports_minibatch:
            self.metrics.log_value((module_id, REACH_VF_LOSS), reach_loss.detach(), window=1)
        return loss + reach_loss
