"""PPOLagTorchLearner: the on-policy base (families/on_policy/learner.py: PPO's clipped surrogate,
both critics, the cost GAE, Ĵ_C, the KL early stop) + the Lagrange multiplier
(families/on_policy/lagrangian.py: ν's step on Ĵ_C before the gradient steps, the surrogate on
A = (A^R − ν·A^C)/(1 + ν)) [O OmniSafe PPOLag]. On RLlib's update path its loss is RLlib's own PPO
loss, the reference the fused path is checked against bit for bit."""

from __future__ import annotations

from lac_rllib.families.on_policy.lagrangian import LagrangianLearner
from lac_rllib.families.on_policy.learner import OnPolicyTorchLearner


class PPOLagTorchLearner(LagrangianLearner, OnPolicyTorchLearner):
    RLLIB_LOSS = True
