"""PPOLag: the on-policy family's training step (families/on_policy/algorithm.py) with PPO-Lag's config."""

from __future__ import annotations

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.families.on_policy.algorithm import OnPolicySafeAlgorithm


class PPOLag(OnPolicySafeAlgorithm):
    CONFIG_CLASS = PPOLagConfig
