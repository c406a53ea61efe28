"""LagrangianLearner: the Lagrange multiplier ν of an on-policy learner, mixed in before it
(PPO-Lag = ``LagrangianLearner`` + ``OnPolicyTorchLearner``; TRPO-Lag = it + the trust-region base).
Source tags: [O] OmniSafe common/lagrange.py and PPOLag, [S] safety-starter-agents PPO-L, [F]
ymzhang01/focops.

- ν takes one projected step per iteration on Ĵ_C, before the gradient steps
  (:meth:`on_cost_window`, the base's hook) [O PPOLag._update: λ first, then the policy];
- the policy's surrogate weighs the Lagrangian advantage A = (A^R − ν·A^C)/(1 + ν)
  [O PPOLag._compute_adv_surrogate];
- ν's rule state is checkpointed beside the base's cost windows; ν itself rides in the module;
- with K constraints, ν_k per constraint, each its own rule on its Ĵ_Ck and limit
  (:class:`~lac_rllib.constrained.lagrange.Multipliers`), and A = (A^R − Σ_k ν_k·A^C_k)/(1 + Σ_k ν_k).
"""

from __future__ import annotations

import torch
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.constrained.lagrange import (
    AdamStep,
    FixedBound,
    GradientStep,
    LagrangeMultiplier,
    Multipliers,
    SoftplusAdamStep,
    fixed_multiplier,
    multipliers_for,
    nu_total,
    nu_weighted,
    restore_multipliers,
)
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES

#: The mixin's entry in the learner's checkpointed state: module id → its multiplier's state.
STATE_KEY = "lagrange"


class LagrangianLearner:
    """Mixed in before an :class:`~lac_rllib.families.on_policy.learner.OnPolicyTorchLearner`
    (or a learner on it); the config has :class:`~lac_rllib.families.on_policy.config.OnPolicyLagParams`."""

    def build(self) -> None:
        super().build()
        self.multipliers = {mid: self.make_multiplier(mid, module) for mid, module in self.module.items()}

    def make_multiplier(self, module_id, module) -> LagrangeMultiplier | Multipliers:
        """ν of ``module``: Adam on ν itself [O common/lagrange.py] or on softplus⁻¹(ν) [S], or the
        plain step of eq. (14) (``nu_optimizer="sgd"`` [F]); held under ``nu_max`` if set; or held
        at ``nu_fixed`` for the whole run. With K constraints, one such ν_k each."""
        config = self.config.get_config_for_module(module_id)
        if held := fixed_multiplier(module.unwrapped().nu, config):
            return held

        def make(value, cost_limit):
            if config.nu_optimizer == "sgd":
                rule = GradientStep(config.lagrangian_lr)
            elif config.nu_parametrization == "direct":
                rule = AdamStep(config.lagrangian_lr)
            else:
                rule = SoftplusAdamStep(config.lagrangian_lr, config.nu_init)
            bound = FixedBound(config.nu_max) if config.nu_max is not None else None
            return LagrangeMultiplier(value, cost_limit=cost_limit, rule=rule, bound=bound, bounded=bound is not None)

        return multipliers_for(module.unwrapped().nu, config, make)

    def on_cost_window(self, module_id, j_c) -> None:
        """ν's one step of the iteration on Ĵ_C (K values with K constraints; None: no episode
        completed yet, no step)."""
        self.multipliers[module_id].step(j_c)

    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """A = (A^R − ν·A^C) / (1 + ν) per row [O PPOLag._compute_adv_surrogate]; with K
        constraints (A^R − Σ_k ν_k·A^C_k) / (1 + Σ_k ν_k)."""
        nu = module.nu.detach()
        return (batch[Postprocessing.ADVANTAGES] - nu_weighted(nu, batch[COST_ADVANTAGES])) / (1.0 + nu_total(nu))

    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[STATE_KEY] = {mid: m.get_state() for mid, m in self.multipliers.items()}
        return state

    def set_state(self, state) -> None:
        super().set_state(state)
        restore_multipliers(self.multipliers, self.module, state.get(STATE_KEY, {}))
