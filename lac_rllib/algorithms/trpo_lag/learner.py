"""TRPOLagTorchLearner: the trust-region base (families/trust_region/learner.py: one TRPO step of
the policy per iteration, the critics' Adam epochs) + the Lagrange multiplier
(families/on_policy/lagrangian.py: ν's step on Ĵ_C first, the step on A = (A^R − ν·A^C)/(1 + ν))
[O OmniSafe TRPOLag]."""

from __future__ import annotations

from lac_rllib.families.on_policy.lagrangian import LagrangianLearner
from lac_rllib.families.trust_region.learner import TrustRegionTorchLearner


class TRPOLagTorchLearner(LagrangianLearner, TrustRegionTorchLearner):
    pass
