"""P3O: the on-policy family's training step (sample, one learner update, sync) with P3O's learner."""

from __future__ import annotations

from lac_rllib.algorithms.p3o.config import P3OConfig
from lac_rllib.families.on_policy.algorithm import OnPolicySafeAlgorithm


class P3O(OnPolicySafeAlgorithm):
    CONFIG_CLASS = P3OConfig
