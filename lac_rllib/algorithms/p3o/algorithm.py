"""P3O(PPOLag): PPO-Lag's training step (sample, one learner update, sync) with P3O's learner."""

from __future__ import annotations

from lac_rllib.algorithms.p3o.config import P3OConfig
from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag


class P3O(PPOLag):
    ALGO, CONFIG_CLASS = "p3o", P3OConfig
