"""CPOTorchLearner: the trust-region base's learner with CPO's step and no multiplier. Source tags: [CPO]
Achiam et al. 2017 (§6.1, §6.2, App. 10.2); [O] OmniSafe cpo.py ``_update_actor``; [S]
safety-starter-agents agents.py ``CPOAgent.update_pi``. The maths is families/trust_region/step.py's.

At the update's first loss call, on the whole batch's real rows (the base's :class:`PolicyOnBatch`):

    g = ∇ mean r·A^R,   b = ∇ mean r·A^C                        [O _loss_pi, _loss_pi_cost]
    x = H⁻¹g, p = H⁻¹b (two conjugate-gradient solves),  q = xᵀHx, r = gᵀp, s = bᵀp
    c = (Ĵ_C − d) / (mean episode length, with cost_gap_scale="episode_length" [S])   [O cpo.py:391]

then the case (0-4) and the step of the linearised problem max gᵀΔ s.t. c + bᵀΔ ≤ 0,
½ΔᵀHΔ ≤ δ: TRPO's step when the whole trust region is feasible (3, 4), (x − ν*p)/λ* from the
closed-form dual (1, 2), the recovery −√(2δ/s)·p when no feasible point is in reach (0); then
the line search [O _cpo_search_step; S]: KL̄ ≤ δ, the cost surrogate rises by at most max(−c, 0),
and in cases 2-4 the reward's loss does not rise. Ĵ_C is the base's cost window; with no episode
completed yet c = −∞ (no known violation: case 3). ``nu`` reports ν* (0 in cases 3-4, the
recovery's √(2δ/s) in case 0 [O Nu_star]); the module's ν stays 0. PCPO replaces
:meth:`constrained_step`.

With K constraints (families/trust_region/multi_constraint.py): b_k and p_k = H⁻¹b_k per constraint
(K + 1 conjugate-gradient solves), c_k from each constraint's window and limit, the K-constraint
step [CPO §6.1: one dual variable per constraint, solved numerically] or PCPO's projection onto the
intersection (:meth:`constrained_step_several`), and the line search holds each cost surrogate.
``nu/NAME`` reports each ν*_k, ``nu`` the largest.
"""

from __future__ import annotations

import collections
import functools
import math

import torch
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.cpo.config import COST_GAP, CPO_CASE
from lac_rllib.algorithms.cpo.episode_lengths import EpisodeLengths
from lac_rllib.constrained.metrics import NU, per_constraint
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.trust_region.learner import PolicyOnBatch, TrustRegionTorchLearner
from lac_rllib.families.trust_region.multi_constraint import CASE_NUMBERS, cpo_step_several, several_acceptance
from lac_rllib.families.trust_region.step import (
    EPS,
    conjugate_gradient,
    cpo_acceptance,
    cpo_step,
    fisher_vector_product,
    flat_grad,
)

#: The learner's own entry in its checkpointed state: the window of episode lengths.
STATE_KEY = "cpo"


class CPOTorchLearner(TrustRegionTorchLearner):
    @override(TrustRegionTorchLearner)
    def build(self) -> None:
        self.episode_lengths = EpisodeLengths()
        super().build()
        # The episodes' lengths, over the same episodes as the cost window (c's scale [S]).
        self.length_windows = {mid: collections.deque(maxlen=self.config.get_config_for_module(mid).cost_window)
                               for mid in self.module.keys()}

    @override(TrustRegionTorchLearner)
    def learner_pieces(self) -> list:
        """The base's, and the episodes' lengths first, before the phantom step is prepended."""
        return [*super().learner_pieces(), ("prepend", self.episode_lengths)]

    def policy_step(self, module_id, config, module, policy: PolicyOnBatch):
        """CPO's step (the module docstring); returns the line search's result, KL̄ and the loss after."""
        reward_adv, cost_adv = policy.whole[Postprocessing.ADVANTAGES], policy.whole[COST_ADVANTAGES]
        if cost_adv.dim() == 2:
            return self.policy_step_several(module_id, config, policy, reward_adv, cost_adv)
        max_kl = policy.max_kl(config)

        def loss() -> torch.Tensor:
            return -policy.surrogate(reward_adv)

        def cost() -> torch.Tensor:
            return policy.surrogate(cost_adv)

        loss_old, cost_old = loss(), cost()
        g, b = -flat_grad(loss_old, policy.params), flat_grad(cost_old, policy.params)
        fvp = fisher_vector_product(policy.mean_kl, policy.params, config.cg_damping)
        x, p = (conjugate_gradient(fvp, v, config.cg_iters, eps=config.cg_eps) for v in (g, b))
        c = self.cost_gap(module_id, config)
        hx = fvp(x)  # H·H⁻¹g: q = xᵀHx [O cpo.py:380], and PCPO's [O]-variant reward step
        step, nu, case, logs = self.constrained_step(config, policy, g, b, x, p, c, max_kl, hx)
        accept = cpo_acceptance(loss, cost, policy.mean_kl, float(loss_old.detach()), float(cost_old.detach()), c,
                                max_kl, case)
        self.metrics.log_dict({NU: nu, COST_GAP: c if math.isfinite(c) else float("nan"), **logs},
                              key=module_id, window=1)
        return self.search(policy, step, accept, config, loss)

    def policy_step_several(self, module_id, config, policy: PolicyOnBatch, reward_adv, cost_adv):
        """The step with K constraints (the module docstring)."""
        max_kl = policy.max_kl(config)

        def loss() -> torch.Tensor:
            return -policy.surrogate(reward_adv)

        cost_fns = [functools.partial(policy.surrogate, cost_adv[:, k]) for k in range(cost_adv.shape[1])]
        loss_old, costs_old = loss(), [fn() for fn in cost_fns]
        g = -flat_grad(loss_old, policy.params)
        B = torch.stack([flat_grad(cost, policy.params) for cost in costs_old])
        fvp = fisher_vector_product(policy.mean_kl, policy.params, config.cg_damping)
        x = conjugate_gradient(fvp, g, config.cg_iters, eps=config.cg_eps)
        P = torch.stack([conjugate_gradient(fvp, b, config.cg_iters, eps=config.cg_eps) for b in B])
        c = self.cost_gaps(module_id, config)
        step, nu, loss_may_rise, case = self.constrained_step_several(config, g, B, x, P, c, max_kl, float(x @ fvp(x)))
        accept = several_acceptance(loss, cost_fns, policy.mean_kl, float(loss_old.detach()),
                                    [float(v.detach()) for v in costs_old], c, max_kl, loss_may_rise=loss_may_rise)
        names = config.constraint_set.names
        self.metrics.log_dict({
            NU: max(nu), CPO_CASE: case, **{per_constraint(NU, n): v for n, v in zip(names, nu)},
            **{per_constraint(COST_GAP, n): v if math.isfinite(v) else float("nan") for n, v in zip(names, c)},
        }, key=module_id, window=1)
        return self.search(policy, step, accept, config, loss)

    def constrained_step_several(self, config, g, B, x, P, c, max_kl, q):
        """(Δθ, ν per constraint, whether the loss may rise in the line search, the case number to
        log): CPO's K-constraint step (multi_constraint.py)."""
        out = cpo_step_several(g, B, x, P, c, max_kl, q=q)
        return out.step_direction, out.nu, out.case == "recovery", CASE_NUMBERS[out.case]

    def cost_gaps(self, module_id, config) -> list[float]:
        """c_k = Ĵ_Ck − b_k per constraint over the base's window, scaled as :meth:`cost_gap`; −∞ each
        with no episode completed yet."""
        lengths = self.length_windows[module_id]
        if lengths.maxlen is None:
            lengths.clear()
        lengths.extend(self.episode_lengths.lengths)
        limits = config.constraint_set.limits
        j_c = self.cost_window_means.get(module_id)
        scaled = config.cost_gap_scale == "episode_length"
        if j_c is None or (scaled and not lengths):
            return [-math.inf] * len(limits)
        scale = (sum(lengths) / len(lengths) + EPS) if scaled else 1.0
        return [(j - b) / scale for j, b in zip(j_c, limits)]

    def constrained_step(self, config, policy: PolicyOnBatch, g, b, x, p, c, max_kl, hx):
        """(Δθ, ν, the case the line search tests, values to log): CPO's [CPO App. 10.2; O cpo.py:215-338].
        ``hx`` = H·x, the damped Fisher product of x = H⁻¹g."""
        out = cpo_step(g, b, x, p, c, max_kl, q=float(x @ hx), convention=config.dual_convention)
        return out.step_direction, out.nu, out.case, {CPO_CASE: out.case}

    def cost_gap(self, module_id, config) -> float:
        """c = Ĵ_C − d over the base's cost window [O: EpCost's window], divided by the mean episode
        length over the same episodes with cost_gap_scale="episode_length" [S: ``c /= (rescale +
        EPS)``, its EpLen]; −∞ with no episode completed yet."""
        lengths = self.length_windows[module_id]
        if lengths.maxlen is None:  # cost_window None: this iteration's episodes only [S]
            lengths.clear()
        lengths.extend(self.episode_lengths.lengths)
        costs = self.cost_windows[module_id]
        scaled = config.cost_gap_scale == "episode_length"
        if not costs or (scaled and not lengths):
            return -math.inf
        c = sum(costs) / len(costs) - config.effective_cost_limit
        return c / (sum(lengths) / len(lengths) + EPS) if scaled else c

    # ----- state: the length window beside the base's cost window -----
    @override(TrustRegionTorchLearner)
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[STATE_KEY] = {mid: list(window) for mid, window in self.length_windows.items()}
        return state

    @override(TrustRegionTorchLearner)
    def set_state(self, state) -> None:
        super().set_state(state)
        for mid, lengths in state.get(STATE_KEY, {}).items():
            self.length_windows[mid].clear()
            self.length_windows[mid].extend(lengths)
