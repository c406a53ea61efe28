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
import functools

import numpy as np
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.annotations import override
from ray.rllib.utils.debug import update_global_seed_if_necessary
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    LEARNER_RESULTS,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)
from ray.rllib.utils.replay_buffers.episode_replay_buffer import EpisodeReplayBuffer
from ray.tune.registry import register_env

from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.algorithms.lac.learner import NU, TS_EPISODE_COST, TS_ITERATION
from lac_rllib.constrained.costs import completed_episode_stats
from lac_rllib.tasks import get_task

# Top-level result keys, declared once (the sweep service and the trainer read these).
# NU ("nu") is the learner's key, reported at the top level under the same name.
EPISODE_RETURN, EPISODE_COST, COST_LIMIT, FEASIBLE = ("episode_return", "episode_cost", "cost_limit", "feasible")
EPISODES_THIS_ITER, ENV_STEPS = "episodes_this_iter", "env_steps"
#: Version of the LAC keys in a checkpoint's rllib_checkpoint.json (see LAC.get_metadata).
CHECKPOINT_FORMAT = 1
#: Key of the replay buffer in the algorithm's checkpointed state (config.store_replay_buffer).
REPLAY_BUFFER = "lac_replay_buffer"


def resume_seed(seed: int, iteration: int) -> int:
    """The seed of a run restored at ``iteration`` (see LAC._reseed_for_restore): a hash of both,
    below 2**31 with room for RLlib's + worker index, so (seed, iteration) pairs do not share streams."""
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1)[0]) % (2**31 - 2**16)


def make_task_env(env_config, task_id: str):
    return get_task(task_id).make(env_config)


def register_task_env(task_id: str) -> None:
    """Make ``task_id`` resolvable by RLlib env runners in every Ray process."""
    register_env(task_id, functools.partial(make_task_env, task_id=task_id))


class LAC(Algorithm):
    @classmethod
    @override(Algorithm)
    def get_default_config(cls) -> LACConfig:
        return LACConfig(cls)

    @override(Algorithm)
    def get_metadata(self) -> dict:
        """RLlib writes this into the checkpoint's ``rllib_checkpoint.json``; the evaluation
        CLI (lac_rllib.evaluation) checks the version/format and reads the task and config."""
        import importlib.metadata
        import json

        cfg = self.config
        lac = {
            "lac_rllib_version": importlib.metadata.version("lac-rllib"),
            "checkpoint_format": CHECKPOINT_FORMAT,
            "task_id": cfg.task_id,
            "seed": cfg.seed,
            "cost_limit": cfg.effective_cost_limit,
            "episode_cost_discount": cfg.effective_episode_cost_discount,
            "lac_config": cfg.lac_params(),
        }
        # JSON-safe (tuples -> lists, anything exotic -> str).
        return {**super().get_metadata(), **json.loads(json.dumps(lac, default=str))}

    @override(Algorithm)
    def setup(self, config) -> None:
        if config.task_id:
            register_task_env(config.task_id)
        super().setup(config)
        self.replay_buffer = EpisodeReplayBuffer(capacity=self.config.replay_capacity)
        self._last_episode_stats = (float("nan"), float("nan"))

    @override(Algorithm)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict:
        state = super().get_state(components, not_components=not_components, **kwargs)
        if self.config.store_replay_buffer and self._check_component(REPLAY_BUFFER, components, not_components):
            state[REPLAY_BUFFER] = self.replay_buffer.get_state()
        return state

    @override(Algorithm)
    def set_state(self, state: dict) -> None:
        super().set_state(state)
        if REPLAY_BUFFER in state:
            self.replay_buffer.set_state(state[REPLAY_BUFFER])

    @override(Algorithm)
    def restore_from_path(self, path, *args, **kwargs) -> None:
        super().restore_from_path(path, *args, **kwargs)
        self._reseed_for_restore()

    def _reseed_for_restore(self) -> None:
        """Fresh random streams for a run restored at iteration k.

        RLlib's checkpoints hold no RNG state: a restored run (``lac-train --resume``, a Tune
        trial restored after a failure or ``sweeps/run.py --resume``) seeds its envs, action
        sampling and torch/numpy as at iteration 0, so its next iteration replays iteration 1's
        random stream: the same env layouts and, in the random phase, the very same transitions
        added to the buffer a second time. Seeding from (seed, k) instead keeps a restored run
        reproducible without repeating data. The streams differ from those of an uninterrupted
        run (which continues its own), so a resumed run is a different draw of the same seed
        (docs/dependencies.md, "Checkpoints and random streams").
        """
        if self.config.seed is None:
            return
        seed = resume_seed(self.config.seed, self.iteration)

        def reseed(runner) -> None:
            # RLlib's SingleAgentEnvRunner seeds its envs with ``_seed`` at its initial reset
            # (and every runner gets seed + worker index, as at construction).
            runner._seed = seed + (runner.worker_index or 0)
            runner._needs_initial_reset = True
            update_global_seed_if_necessary(runner.config.framework_str, runner._seed)

        self.env_runner_group.foreach_env_runner(reseed, local_env_runner=True)
        self.learner_group.foreach_learner(lambda learner: update_global_seed_if_necessary("torch", seed))

    @override(Algorithm)
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
                TS_EPISODE_COST: float(np.mean(costs)) if costs else None,
                TS_ITERATION: self.iteration,
            },
            minibatch_size=cfg.lac_minibatch_size,
            num_total_minibatches=max(1, int(cfg.gradient_passes * n_rows / cfg.lac_minibatch_size)),
        )
        self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True)
        self._log_top_level(returns, costs)

    def _log_top_level(self, returns, costs) -> None:
        """episode_return / episode_cost: means over the episodes completed this iteration
        (the last known values carry over an iteration in which none completed)."""
        if returns:
            self._last_episode_stats = (float(np.mean(returns)), float(np.mean(costs)))
        ret, cost = self._last_episode_stats
        limit = self.config.effective_cost_limit
        nu = self.metrics.peek((LEARNER_RESULTS, DEFAULT_MODULE_ID, NU), default=float("nan"))
        for key, value in {
            EPISODE_RETURN: ret, EPISODE_COST: cost, COST_LIMIT: limit,
            FEASIBLE: float(cost <= limit), NU: float(nu), EPISODES_THIS_ITER: len(returns),
            ENV_STEPS: self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0),
        }.items():
            self.metrics.log_value(key, value, window=1)
