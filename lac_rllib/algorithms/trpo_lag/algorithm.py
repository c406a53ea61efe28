"""TRPOLag: the on-policy family's training step (constrained/on_policy.py: sample, one learner
update, sync) with the trust-region learner: the update call's critic minibatches are the
config's (minibatch_size, num_epochs), the policy's one step happens inside it (learner.py)."""

from __future__ import annotations

from lac_rllib.algorithms.trpo_lag.config import TRPOLagConfig
from lac_rllib.constrained.on_policy import OnPolicySafeAlgorithm


class TRPOLag(OnPolicySafeAlgorithm):
    CONFIG_CLASS = TRPOLagConfig
