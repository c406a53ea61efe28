"""PCPO(CPO): CPO's training step (PPO-Lag's: sample, one learner update, sync) with PCPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.cpo.algorithm import CPO
from lac_rllib.algorithms.pcpo.config import PCPOConfig


class PCPO(CPO):
    ALGO, CONFIG_CLASS = "pcpo", PCPOConfig
