"""OffPolicySafeAlgorithm: a SafeAlgorithm that learns from a replay buffer of episodes.

Each iteration samples into an ``EpisodeReplayBuffer`` (it keeps infos, hence the per-step cost)
and then makes *one* ``learner_group.update`` call over the whole buffer, whatever the number of
minibatches (docs/dependencies.md, "Cost of an update call": each call costs ~0.1 s, so not one
call per minibatch). The buffer is part of the checkpoint when ``store_replay_buffer``.

The config of a subclass has ``replay_capacity`` and ``store_replay_buffer``.
"""

from __future__ import annotations

import copy

from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, LEARNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.rllib.utils.replay_buffers.episode_replay_buffer import EpisodeReplayBuffer

from lac_rllib.constrained.algorithm import SafeAlgorithm
from lac_rllib.constrained.costs import completed_constraint_costs, completed_episode_stats

#: Key of the replay buffer in the algorithm's checkpointed state (the name checkpoints carry since 0.1).
REPLAY_BUFFER = "lac_replay_buffer"


class OffPolicySafeAlgorithm(SafeAlgorithm):
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

    @property
    def lifetime_env_steps(self):
        """Env steps sampled so far (RLlib's lifetime count, as its metrics hold it)."""
        return self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)

    def sample_into_replay(self, *, random_actions: bool) -> tuple[list[float], list[float]]:
        """Sample ``env_steps_per_iteration`` env steps into the buffer; the (returns, costs) of the
        episodes that completed in them (with several constraints, each one's K costs are kept in
        ``constraint_costs``)."""
        cfg = self.config
        episodes, runner_results = synchronous_parallel_sample(
            worker_set=self.env_runner_group,
            max_env_steps=cfg.env_steps_per_iteration,
            random_actions=random_actions,
            sample_timeout_s=cfg.sample_timeout_s,
            _uses_new_env_runners=True,
            _return_metrics=True,
        )
        self.metrics.aggregate(runner_results, key=ENV_RUNNER_RESULTS)
        returns, costs = completed_episode_stats(episodes)
        #: With several constraints: each episode completed in the latest sample, its K costs.
        self.constraint_costs = completed_constraint_costs(episodes)
        for episode in episodes:
            # The learners never read logp/dist inputs (off-policy, their own targets); and chunks
            # of random-action iterations have none, so a chunk from each side of the switch
            # could not be concatenated in the buffer. Dropping them saves memory too.
            episode.extra_model_outputs.clear()
        self.replay_buffer.add(episodes)
        return returns, costs

    def update_from_replay(self, *, timesteps: dict, **update_kwargs) -> None:
        """One ``learner_group.update`` over the whole buffer (the learner connector shuffles or
        draws its rows), then the new weights to the env runners. ``update_kwargs`` go to
        ``learner_group.update`` (``minibatch_size``, ``num_total_minibatches``, ``num_epochs``,
        ``shuffle_batch_per_epoch``, as constrained/minibatch_loop.py's ``update_kwargs`` gives them)."""
        learner_results = self.learner_group.update(
            # Shallow copies: the learner connector renames episode ids in place
            # (AddObservationsFromEpisodesToBatch appends "_i"), which would break the
            # buffer's id → episode map when the next chunk of an ongoing episode arrives.
            episodes=[copy.copy(e) for e in self.replay_buffer.episodes],
            timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: self.lifetime_env_steps, **timesteps},
            **update_kwargs,
        )
        self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        self.env_runner_group.sync_weights(from_worker_or_learner_group=self.learner_group, inference_only=True)
