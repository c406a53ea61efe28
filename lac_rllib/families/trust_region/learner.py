"""TrustRegionTorchLearner: the on-policy base (families/on_policy/learner.py) whose policy takes one
trust-region step per iteration: TRPO on :meth:`policy_advantages` (A^R; TRPO-Lag's multiplier
weighs A^C in), CPO and PCPO replace :meth:`policy_step`. Source tags: [O] OmniSafe natural_pg.py,
trpo.py, trpo_lag.py; [S] safety-starter-agents agents.py ``TRPOAgent``; [TRPO] Schulman et al.
2015, App. C. The maths is families/trust_region/step.py's.

One ``update`` call is one iteration. Ĵ_C first (and with a multiplier ν's step on it [O
TRPOLag._update]), then, at the update's first loss call (the batch exists only once the learner
connector has run, after ``before_gradient_based_update``), before any critic step [O
NaturalPG._update: the actor first], the policy's step on the whole batch's real rows
(``LOSS_MASK``), with π_old the behaviour policy (its distribution inputs and log-probabilities in
the batch) and A the learner's advantage (TRPO-Lag's (A^R − ν·A^C)/(1 + ν) [O
TRPOLag._compute_adv_surrogate]):

    L(θ) = −mean r(θ)·A,   r = π_θ(a|s)/π_old(a|s)                           [O policy_gradient.py _loss_pi]
    g = −∇L,   x ≈ (H + damping·I)⁻¹g by conjugate gradient, H the Hessian of
    KL̄(θ) = mean KL(π_old ‖ π_θ)                                              [TRPO App. C; O _fvp]
    Δθ = √(2δ/xᵀHx)·x, then θ_old + c^j·Δθ for the first j whose KL̄ ≤ δ and L ≤ L(θ_old),
    θ_old if none is                                                          [O _search_step_size; S update_pi]

δ = target_kl·act_dim with kl_per_action_dim (config.py); with kl_convention="mean" the KL is
averaged over the action's dimensions [O] and δ = target_kl. The critics then take their Adam
minibatch epochs in the same call (the base's loop, fused or RLlib's), the policy's per-row loss
there being nothing; there is no KL early stop.
"""

from __future__ import annotations

import math

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import TorchDiagGaussian
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override

from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.learner import EpochProgress, OnPolicyTorchLearner, gaussian_logp
from lac_rllib.families.trust_region.config import LINE_SEARCH_BACKTRACKS, LINE_SEARCH_FRACTION
from lac_rllib.families.trust_region.step import (
    LineSearchResult,
    conjugate_gradient,
    fisher_vector_product,
    flat_grad,
    line_search,
    masked_mean,
    trpo_acceptance,
    trpo_step,
)

#: The whole batch's columns the step reads (``CostGAE.last_batch``).
WHOLE_BATCH_COLUMNS = (Columns.OBS, Columns.ACTIONS, Columns.ACTION_LOGP, Columns.LOSS_MASK,
                       Postprocessing.ADVANTAGES, COST_ADVANTAGES)


class PolicyOnBatch:
    """The policy's surrogates and mean KL on the real rows of the whole batch, as functions of its
    current parameters (``params``: the actor's encoder and head, log σ included).

    π_old of the KL is the policy as the step starts [O trpo.py ``p_dist``], so KL̄(θ_old) = 0 and
    its Hessian is the Fisher matrix for any batch; the behaviour policy [S ``pi_info``] is the same
    one (the env runners act with the weights of the last update). The ratio's denominator is the
    behaviour log-probability [O, S]."""

    def __init__(self, module, whole: dict, kl_convention: str = "sum"):
        self.module, self.whole = module, whole
        self.params = [p for net in (module.encoder.actor_encoder, module.pi) for p in net.parameters()]
        self.mask = whole[Columns.LOSS_MASK]
        self.dist_cls = module.get_train_action_dist_cls()
        shape = getattr(module.action_space, "shape", None)
        self.action_dims = int(math.prod(shape)) if shape else 1
        #: The action dimensions the step's KL sums over: all of them, or 1 for their mean (kl_convention).
        self.kl_dims = self.action_dims if kl_convention == "sum" else 1
        with torch.no_grad():
            self.old = self.dist_cls.from_logits(module.action_dist_inputs(whole[Columns.OBS]))

    def surrogate(self, advantages: torch.Tensor) -> torch.Tensor:
        """mean r·A over the real rows, r = π_θ(a|s)/π_old(a|s) from the behaviour log-probabilities."""
        inputs = self.module.action_dist_inputs(self.whole[Columns.OBS])
        actions = self.whole[Columns.ACTIONS]
        logp = (gaussian_logp(inputs, actions) if self.dist_cls is TorchDiagGaussian
                else self.dist_cls.from_logits(inputs).logp(actions))
        return masked_mean(torch.exp(logp - self.whole[Columns.ACTION_LOGP]) * advantages, self.mask)

    def mean_kl(self) -> torch.Tensor:
        """KL̄ = mean KL(π_old ‖ π_θ) over the real rows: RLlib's KL (summed over action dimensions),
        or its mean over them [O natural_pg.py:95] (kl_convention)."""
        new = self.dist_cls.from_logits(self.module.action_dist_inputs(self.whole[Columns.OBS]))
        kl = self.old.kl(new)
        return masked_mean(kl if self.kl_dims == self.action_dims else kl / self.action_dims, self.mask)

    def max_kl(self, config) -> float:
        """δ on this KL (config.max_kl: per action dimension or summed, on the convention's KL)."""
        return config.max_kl(self.action_dims)


class TrustRegionTorchLearner(OnPolicyTorchLearner):
    @override(OnPolicyTorchLearner)
    def build(self) -> None:
        super().build()
        self.cost_gae.kept_columns = WHOLE_BATCH_COLUMNS  # the step reads the whole batch
        self.step_due: set[str] = set()
        self.step_loss: dict[str, torch.Tensor] = {}

    def optimizer_groups(self, module, config) -> dict:
        """Adam for the two critics only [O: no actor optimizer step in NaturalPG._update]."""
        return self.critic_groups(module, config)

    @override(OnPolicyTorchLearner)
    def before_gradient_based_update(self, *, timesteps) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # Ĵ_C (ν's step) first [O TRPOLag._update]
        self.step_due = set(self.module.keys())

    @override(OnPolicyTorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        if module_id in self.step_due:  # the update's first loss call: before any critic step
            self.step_due.discard(module_id)
            whole = self.cost_gae.last_batch.get(module_id)
            if whole is None:
                raise RuntimeError("the trust-region step needs the whole batch its learner connector's cost GAE keeps")
            module = self.module[module_id].unwrapped()
            policy = PolicyOnBatch(module, whole, config.kl_convention)
            result, kl, loss = self.policy_step(module_id, config, module, policy)
            self.progress.setdefault(module_id, EpochProgress()).kl = kl  # reported as kl_full_batch
            self.step_loss[module_id] = torch.tensor(loss)
            self.metrics.log_dict({LINE_SEARCH_FRACTION: result.fraction, LINE_SEARCH_BACKTRACKS: result.backtracks},
                                  key=module_id, window=1)
        return super().compute_loss_for_module(module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)

    def policy_step(self, module_id, config, module, policy: PolicyOnBatch) -> tuple[LineSearchResult, float, float]:
        """TRPO's step on :meth:`policy_advantages` (the module docstring); returns the line search's
        result and the mean KL and the loss L after it."""
        advantages = self.policy_advantages(config, module, policy.whole).detach()
        max_kl = policy.max_kl(config)

        def loss() -> torch.Tensor:
            return -policy.surrogate(advantages)

        loss_old = loss()
        g = -flat_grad(loss_old, policy.params)
        fvp = fisher_vector_product(policy.mean_kl, policy.params, config.cg_damping)
        x = conjugate_gradient(fvp, g, config.cg_iters, eps=config.cg_eps)
        step = trpo_step(x, x @ fvp(x), max_kl)  # q = xᵀHx [O trpo.py; S agents.py]
        accept = trpo_acceptance(loss, policy.mean_kl, float(loss_old.detach()), max_kl)
        return self.search(policy, step, accept, config, loss)

    def search(self, policy: PolicyOnBatch, step: torch.Tensor, accept, config, loss
               ) -> tuple[LineSearchResult, float, float]:
        """The backtracking line search from θ_old along ``step`` (none if the step is not finite:
        [O] asserts), then KL̄ and ``loss()`` where it left the parameters."""
        if torch.isfinite(step).all():
            result = line_search(policy.params, step, accept, backtracks=config.backtrack_iters,
                                 decay=config.backtrack_coeff)
        else:
            result = LineSearchResult(False, 0.0, 0)
        with torch.no_grad():
            return result, float(policy.mean_kl()), float(loss())

    # ----- the critics' epochs -----
    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """No per-row term: the policy stepped already. The step's loss after the line search rides
        as a constant (no gradient), so ``policy_loss`` reports it."""
        return torch.zeros_like(advantages), self.step_loss.get(module_id)

    def check_kl_at_epoch_end(self, module_id, config, module, *, minibatch_rows: int) -> None:
        """No KL early stop (the line search bounds the KL): count the rows only."""
        self.progress.setdefault(module_id, EpochProgress()).rows += minibatch_rows

    def stopped_optimizers(self, module_id) -> tuple[str, ...]:
        return ()
