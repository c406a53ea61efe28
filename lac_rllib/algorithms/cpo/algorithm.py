"""CPO: the on-policy family's training step (constrained/on_policy.py: sample, one learner update,
sync) with CPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.cpo.config import CPOConfig
from lac_rllib.constrained.on_policy import OnPolicySafeAlgorithm


class CPO(OnPolicySafeAlgorithm):
    CONFIG_CLASS = CPOConfig
