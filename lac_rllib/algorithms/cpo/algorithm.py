"""CPO(TRPOLag): TRPO-Lag's training step (PPO-Lag's: sample, one learner update, sync) with CPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.cpo.config import CPOConfig
from lac_rllib.algorithms.trpo_lag.algorithm import TRPOLag


class CPO(TRPOLag):
    ALGO, CONFIG_CLASS = "cpo", CPOConfig
