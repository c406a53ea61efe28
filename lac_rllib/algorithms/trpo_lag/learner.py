"""TRPOLagTorchLearner: the trust-region base (constrained/trust_region_learner.py: one TRPO step of
the policy per iteration, the critics' Adam epochs) + the Lagrange multiplier
(constrained/lagrangian_learner.py: ν's step on Ĵ_C first, the step on A = (A^R − ν·A^C)/(1 + ν))
[O OmniSafe TRPOLag]."""

from __future__ import annotations

from lac_rllib.constrained.lagrangian_learner import LagrangianLearner
from lac_rllib.constrained.trust_region_learner import TrustRegionTorchLearner


class TRPOLagTorchLearner(LagrangianLearner, TrustRegionTorchLearner):
    pass
