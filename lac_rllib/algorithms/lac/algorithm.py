"""LAC(Algorithm): Algorithm 2 of the paper on RLlib's new API stack.

One ``training_step`` = one iteration k of Algorithm 2:
  1. sample ``env_steps_per_iteration`` steps with the generator π_φ (uniform random actions
     in the first ``random_iterations`` iterations [C]);
  2. store them in an ``EpisodeReplayBuffer`` (it keeps infos, hence the per-step cost);
  3. ν update (eq. 14) from the episodes completed in this batch, inside the Learner, before
  4. one pass of minibatches over the whole buffer in a single ``learner_group.update`` call
     (docs/dependencies.md, "Cost of an update call": each call costs ~0.1 s, so not one call per minibatch).
"""

from __future__ import annotations

import copy

import numpy as np
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    LEARNER_RESULTS,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)
from ray.rllib.utils.replay_buffers.episode_replay_buffer import EpisodeReplayBuffer

from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.constrained.algorithm import SafeAlgorithm
from lac_rllib.constrained.costs import completed_episode_stats
from lac_rllib.constrained.metrics import TS_ITERATION, TS_MEAN_EPISODE_COST

#: Key of the replay buffer in the algorithm's checkpointed state (config.store_replay_buffer).
REPLAY_BUFFER = "lac_replay_buffer"


class LAC(SafeAlgorithm):
    ALGO = "lac"

    @classmethod
    @override(SafeAlgorithm)
    def get_default_config(cls) -> LACConfig:
        return LACConfig(cls)

    @override(SafeAlgorithm)
    def setup(self, config) -> None:
        super().setup(config)
        self.replay_buffer = EpisodeReplayBuffer(capacity=self.config.replay_capacity)

    @override(SafeAlgorithm)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict:
        state = super().get_state(components, not_components=not_components, **kwargs)
        if self.config.store_replay_buffer and self._check_component(REPLAY_BUFFER, components, not_components):
            state[REPLAY_BUFFER] = self.replay_buffer.get_state()
        return state

    @override(SafeAlgorithm)
    def set_state(self, state: dict) -> None:
        super().set_state(state)
        if REPLAY_BUFFER in state:
            self.replay_buffer.set_state(state[REPLAY_BUFFER])

    @override(SafeAlgorithm)
    def training_step(self) -> None:
        cfg = self.config
        episodes, runner_results = synchronous_parallel_sample(
            worker_set=self.env_runner_group,
            max_env_steps=cfg.env_steps_per_iteration,
            random_actions=self.iteration < cfg.random_iterations,
            sample_timeout_s=cfg.sample_timeout_s,
            _uses_new_env_runners=True,
            _return_metrics=True,
        )
        self.metrics.aggregate(runner_results, key=ENV_RUNNER_RESULTS)
        returns, costs = completed_episode_stats(episodes)
        for episode in episodes:
            # LAC never reads logp/dist inputs (off-policy, its own targets); and chunks of
            # random-action iterations have none, so a chunk from each side of the switch
            # could not be concatenated in the buffer. Dropping them saves memory too.
            episode.extra_model_outputs.clear()
        self.replay_buffer.add(episodes)

        n_rows = self.replay_buffer.get_num_timesteps()
        learner_results = self.learner_group.update(
            # Shallow copies: the learner connector renames episode ids in place
            # (AddObservationsFromEpisodesToBatch appends "_i"), which would break the
            # buffer's id → episode map when the next chunk of an ongoing episode arrives.
            episodes=[copy.copy(e) for e in self.replay_buffer.episodes],
            timesteps={
                NUM_ENV_STEPS_SAMPLED_LIFETIME: self.metrics.peek(
                    (ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0),
                # eq. (14) uses only episodes that completed in this batch [C].
                TS_MEAN_EPISODE_COST: float(np.mean(costs)) if costs else None,
                TS_ITERATION: self.iteration,
            },
            minibatch_size=cfg.lac_minibatch_size,
            num_total_minibatches=max(1, int(cfg.gradient_passes * n_rows / cfg.lac_minibatch_size)),
        )
        self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True)
        self.log_top_level(returns, costs)
