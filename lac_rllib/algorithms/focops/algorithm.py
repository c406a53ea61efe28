"""FOCOPS(PPOLag): PPO-Lag's training step (sample, one learner update, sync) with FOCOPS's learner."""

from __future__ import annotations

from lac_rllib.algorithms.focops.config import FOCOPSConfig
from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag


class FOCOPS(PPOLag):
    CONFIG_CLASS = FOCOPSConfig
