"""PCPOTorchLearner: CPO's learner with PCPO's step. Source tags: [P] Yang et al. 2020, eq. 7;
[O] OmniSafe pcpo.py ``_update_actor``. The maths is families/trust_region/step.py's ``pcpo_step``.

With CPO's g, b, x = H⁻¹g, p = H⁻¹b and c (cpo/learner.py), the step is the reward's TRPO step
projected onto {Δ: c + bᵀΔ ≤ 0} (``projection``: the KL metric [P], the Euclidean one, or
[O]'s variant along η·Hx ≈ η·g in [O]'s units, its KL averaged over the action's dimensions),
then CPO's line search as [O] calls it for PCPO: case 0, so the reward's loss may rise, the cost
surrogate by at most max(−c, 0), and KL̄ ≤ δ [O pcpo.py:111-124, 200 tries]. ``nu`` reports the
projection's coefficient, 0 when the reward's step is feasible.

With K constraints the reward step is projected onto the intersection of the K half-spaces
(multi_constraint.py ``pcpo_step_several``; ``projection`` "kl" or "l2"), ν one coefficient each.
"""

from __future__ import annotations

from lac_rllib.algorithms.cpo.learner import CPOTorchLearner
from lac_rllib.families.trust_region.multi_constraint import pcpo_step_several
from lac_rllib.families.trust_region.step import pcpo_step


class PCPOTorchLearner(CPOTorchLearner):
    def constrained_step(self, config, policy, g, b, x, p, c, max_kl, hx):
        """(Δθ, ν, the case the line search tests, values to log): PCPO's [P eq. 7; O pcpo.py:102-109]."""
        out = pcpo_step(g, b, x, p, c, max_kl, metric=config.projection, q=float(x @ hx), hx=hx,
                        kl_dims=policy.kl_dims)
        return out.step_direction, out.nu, 0, {}

    def constrained_step_several(self, config, g, B, x, P, c, max_kl, q):
        """PCPO's projection onto the K half-spaces' intersection; its line search as case 0 (the loss
        may rise) [O pcpo.py:111-124]."""
        # [O]'s variant is a one-constraint step; with several its projection is the KL one [P].
        metric = "kl" if config.projection == "omnisafe" else config.projection
        out = pcpo_step_several(g, B, x, P, c, max_kl, metric=metric, q=q)
        return out.step_direction, out.nu, True, 0
