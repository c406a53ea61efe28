"""P3OTorchLearner: PPO's clipped loss on A^R plus P3O's exact penalty. Source tag: [O] OmniSafe
p3o.py (``_loss_pi_cost``, ``_update_actor``).

Per minibatch, one loss through the policy's optimizer (Zhang et al. 2022, eq. 9):

    L = −mean( min(r·A^R, clip(r, 1 ± ε)·A^R) ) + κ·ReLU( mean(r·A^C) + (Ĵ_C − b) ),

r = π_θ(a|s)/π_old(a|s), the cost surrogate unclipped [O], Ĵ_C the mean cost of the last
``cost_window`` completed episodes (the on-policy base's window; with no episode completed yet, no
penalty).
Below the limit by more than the surrogate can move the penalty is 0 and so is its gradient; above
it, the policy descends κ·mean(r·A^C). No multiplier: the module's ν stays 0 (the base's A^R alone
in the clipped term); ``nu`` reports the penalty's active weight κ·1[penalty > 0] of the last
minibatch.

With K constraints, a penalty per constraint (the paper's multi-constraint form, Zhang et al. 2022
§4.3): Σ_k κ·ReLU(mean(r·A^C_k) + (Ĵ_Ck − b_k)), each on its own cost advantage, window and limit;
``nu/NAME`` reports each one's active weight, ``nu`` the largest.
"""

from __future__ import annotations

import torch
from ray.rllib.core.columns import Columns

from lac_rllib.algorithms.p3o.config import COST_PENALTY
from lac_rllib.constrained.metrics import NU, per_constraint
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.learner import OnPolicyTorchLearner


def p3o_penalty(ratio: torch.Tensor, cost_advantages: torch.Tensor, cost_gap: float, kappa: float,
                mean) -> torch.Tensor:
    """κ·ReLU(mean(r·A^C) + (Ĵ_C − b)), ``mean`` the masked mean over the real rows [O _loss_pi_cost]."""
    return kappa * torch.relu(mean(ratio * cost_advantages) + cost_gap)


class P3OTorchLearner(OnPolicyTorchLearner):
    def before_gradient_based_update(self, *, timesteps) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # fills the cost windows
        self.cost_gaps = {}
        for mid, window in self.cost_windows.items():
            config = self.config.get_config_for_module(mid)
            several = config.several_constraints
            if several is not None:  # K gaps Ĵ_Ck − b_k
                j_c = self.cost_window_means.get(mid)
                self.cost_gaps[mid] = None if j_c is None else [c - b for c, b in zip(j_c, several.limits)]
                continue
            limit = config.effective_cost_limit
            self.cost_gaps[mid] = float(sum(window) / len(window)) - limit if window else None

    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """PPO's clipped loss per row, and the penalty as the minibatch's term (the module docstring)."""
        rows, _ = super().policy_loss(module_id, config, module, batch, logits, logp, advantages, masked_mean)
        gap = getattr(self, "cost_gaps", {}).get(module_id)
        if gap is None:  # no episode completed yet: Ĵ_C unknown, no penalty
            return rows, None
        ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])
        if isinstance(gap, list):  # K constraints: a penalty each, summed
            parts = [p3o_penalty(ratio, batch[COST_ADVANTAGES][:, k], g, config.kappa, masked_mean)
                     for k, g in enumerate(gap)]
            if self.reports_minibatch:
                names = config.constraint_set.names
                active = {per_constraint(NU, n): config.kappa * float(p > 0) for n, p in zip(names, parts)}
                self.metrics.log_dict({COST_PENALTY: sum(p.detach() for p in parts),
                                       NU: max(active.values()), **active}, key=module_id, window=1)
            return rows, sum(parts)
        penalty = p3o_penalty(ratio, batch[COST_ADVANTAGES], gap, config.kappa, masked_mean)
        if self.reports_minibatch:
            self.metrics.log_dict({COST_PENALTY: penalty.detach(), NU: config.kappa * float(penalty > 0)},
                                  key=module_id, window=1)
        return rows, penalty
