"""TRPOLag: the on-policy family's training step (families/on_policy/algorithm.py: sample, one learner
update, sync) with the trust-region learner: the update call's critic minibatches are the
config's (minibatch_size, num_epochs), the policy's one step happens inside it (learner.py)."""

from __future__ import annotations

from lac_rllib.algorithms.trpo_lag.config import TRPOLagConfig
from lac_rllib.families.on_policy.algorithm import OnPolicySafeAlgorithm


class TRPOLag(OnPolicySafeAlgorithm):
    CONFIG_CLASS = TRPOLagConfig
