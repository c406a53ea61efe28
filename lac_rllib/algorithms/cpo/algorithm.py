"""CPO: the on-policy family's training step (families/on_policy/algorithm.py: sample, one learner update,
sync) with CPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.cpo.config import CPOConfig
from lac_rllib.families.on_policy.algorithm import OnPolicySafeAlgorithm


class CPO(OnPolicySafeAlgorithm):
    CONFIG_CLASS = CPOConfig
