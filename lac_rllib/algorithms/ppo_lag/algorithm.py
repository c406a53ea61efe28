"""PPOLag: the on-policy family's training step (constrained/on_policy.py) with PPO-Lag's config."""

from __future__ import annotations

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained.on_policy import OnPolicySafeAlgorithm


class PPOLag(OnPolicySafeAlgorithm):
    CONFIG_CLASS = PPOLagConfig
