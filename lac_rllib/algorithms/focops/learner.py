"""FOCOPSTorchLearner: PPO-Lag's learner with FOCOPS's policy loss. Source tags: [O] OmniSafe
focops.py, [F] ymzhang01/focops focops_main.py.

The loss of Zhang et al. (2020), eq. (11), per state s of the minibatch, with π_old the behaviour
policy of the batch (its distribution inputs ride in the batch: ``ACTION_DIST_INPUTS``, the
policy at the start of the update, which [O] snapshots as ``_p_dist``):

    L(s) = ( KL(π_θ ‖ π_old)[s] − (1/λ_F)·r(s, a)·A(s, a) ) · 1[ KL(π_θ ‖ π_old)[s] ≤ η ],

r = π_θ(a|s)/π_old(a|s), A = (A^R − ν·A^C)/(1 + ν) [O] or A^R − ν·A^C [F], averaged over the real
rows (a dropped row counts as 0, as [O]'s mean over the minibatch). Its gradient is the
first-order step towards π* ∝ π_old·exp(A/λ_F) inside the trust region (``focops_indicator=
"per_row"``, the ``paper`` preset). OmniSafe's loss, the default (``"broadcast"``), multiplies the
(B, 1) indicator into the (B,) term [O focops.py:103-107]: its B × B mean keeps every row's
surrogate gradient, scaled by the fraction f of rows inside η,

    L = mean_i( 1_i·KL_i ) − f·mean_j( r_j·A_j )/λ_F.

The critics, ν's step (capped at ``nu_max``) and the epoch-level KL stop are PPO-Lag's.
"""

from __future__ import annotations

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms.focops.config import TRUST_REGION_FRACTION
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.lagrange import nu_total, nu_weighted
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.projection import kl_to_reference, within


class FOCOPSTorchLearner(PPOLagTorchLearner):
    RLLIB_LOSS = False
    MINIBATCH_COLUMNS = (*PPOLagTorchLearner.MINIBATCH_COLUMNS, Columns.ACTION_DIST_INPUTS)

    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """A = (A^R − ν·A^C)/(1 + ν) [O], or A^R − ν·A^C with ``nu_divides_advantage=False`` [F]; with
        K constraints Σ_k ν_k·A^C_k and 1 + Σ_k ν_k."""
        nu = module.nu.detach()
        advantages = batch[Postprocessing.ADVANTAGES] - nu_weighted(nu, batch[COST_ADVANTAGES])
        return advantages / (1.0 + nu_total(nu)) if config.nu_divides_advantage else advantages

    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """Eq. (11) per row (the module docstring), or OmniSafe's broadcast of it
        (``focops_indicator="broadcast"``): its B × B mean written per row, 1_i·kl_i − f·r_i·A_i/λ_F
        with f = mean_j 1_j, whose mean over the rows is [O]'s mean over the matrix."""
        dist_cls = module.get_train_action_dist_cls()
        kl = kl_to_reference(dist_cls, logits, batch[Columns.ACTION_DIST_INPUTS])
        inside = within(kl, config.focops_eta)
        ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])
        if self.reports_minibatch:
            self.metrics.log_value((module_id, TRUST_REGION_FRACTION), masked_mean(inside), window=1)
        if config.focops_indicator == "broadcast":
            return kl * inside - masked_mean(inside) * ratio * advantages / config.focops_lam, None
        return (kl - ratio * advantages / config.focops_lam) * inside, None
