"""TRPOLag(PPOLag): PPO-Lag's training step (sample, one learner update, sync) with the trust-region
learner: the update call's critic minibatches are the config's (minibatch_size, num_epochs), the
policy's one step happens inside it (learner.py)."""

from __future__ import annotations

from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag
from lac_rllib.algorithms.trpo_lag.config import TRPOLagConfig


class TRPOLag(PPOLag):
    ALGO, CONFIG_CLASS = "trpo_lag", TRPOLagConfig
