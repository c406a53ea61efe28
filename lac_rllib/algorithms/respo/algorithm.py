"""RESPO(PPOLag): PPO-Lag's training step (sample, one learner update, sync) with RESPO's learner."""

from __future__ import annotations

from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag
from lac_rllib.algorithms.respo.config import RESPOConfig


class RESPO(PPOLag):
    CONFIG_CLASS = RESPOConfig
