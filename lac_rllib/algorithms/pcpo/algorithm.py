"""PCPO(CPO): CPO's training step (the on-policy family's: sample, one learner update, sync) with PCPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.cpo.algorithm import CPO
from lac_rllib.algorithms.pcpo.config import PCPOConfig


class PCPO(CPO):
    CONFIG_CLASS = PCPOConfig
