"""P3OTorchLearner: PPO's clipped loss on A^R plus P3O's exact penalty. Source tag: [O] OmniSafe
p3o.py (``_loss_pi_cost``, ``_update_actor``).

Per minibatch, one loss through the policy's optimizer (Zhang et al. 2022, eq. 9):

    L = −mean( min(r·A^R, clip(r, 1 ± ε)·A^R) ) + κ·ReLU( mean(r·A^C) + (Ĵ_C − b) ),

r = π_θ(a|s)/π_old(a|s), the cost surrogate unclipped [O], Ĵ_C the mean cost of the last
``cost_window`` completed episodes (PPO-Lag's window; with no episode completed yet, no penalty).
Below the limit by more than the surrogate can move the penalty is 0 and so is its gradient; above
it, the policy descends κ·mean(r·A^C). The module's ν stays 0 (A^R alone in the clipped term);
``nu`` reports the penalty's active weight κ·1[penalty > 0] of the last minibatch.
"""

from __future__ import annotations

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms.ppo_lag.cost_gae import COST_ADVANTAGES
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.lagrange import GradientStep, LagrangeMultiplier
from lac_rllib.constrained.metrics import COST_PENALTY, NU


def p3o_penalty(ratio: torch.Tensor, cost_advantages: torch.Tensor, cost_gap: float, kappa: float,
                mean) -> torch.Tensor:
    """κ·ReLU(mean(r·A^C) + (Ĵ_C − b)), ``mean`` the masked mean over the real rows [O _loss_pi_cost]."""
    return kappa * torch.relu(mean(ratio * cost_advantages) + cost_gap)


class P3OTorchLearner(PPOLagTorchLearner):
    RLLIB_LOSS = False

    def make_multiplier(self, module_id, module) -> LagrangeMultiplier:
        """No multiplier: ν pinned at 0 (a zero step), so PPO-Lag's bookkeeping of Ĵ_C runs as it is."""
        config = self.config.get_config_for_module(module_id)
        return LagrangeMultiplier(module.unwrapped().nu, cost_limit=config.effective_cost_limit,
                                  rule=GradientStep(0.0), bounded=False)

    def before_gradient_based_update(self, *, timesteps) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # fills the cost windows
        self.cost_gaps = {}
        for mid, window in self.cost_windows.items():
            limit = self.config.get_config_for_module(mid).effective_cost_limit
            self.cost_gaps[mid] = float(sum(window) / len(window)) - limit if window else None

    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """A^R alone: the cost enters through the penalty [O: PPO's _compute_adv_surrogate]."""
        return batch[Postprocessing.ADVANTAGES]

    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """PPO's clipped loss per row, and the penalty as the minibatch's term (the module docstring)."""
        rows, _ = super().policy_loss(module_id, config, module, batch, logits, logp, advantages, masked_mean)
        gap = getattr(self, "cost_gaps", {}).get(module_id)
        if gap is None:  # no episode completed yet: Ĵ_C unknown, no penalty
            return rows, None
        ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])
        penalty = p3o_penalty(ratio, batch[COST_ADVANTAGES], gap, config.kappa, masked_mean)
        if self.reports_minibatch:
            self.metrics.log_dict({COST_PENALTY: penalty.detach(), NU: config.kappa * float(penalty > 0)},
                                  key=module_id, window=1)
        return rows, penalty
