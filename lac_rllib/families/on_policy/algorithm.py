"""OnPolicySafeAlgorithm(SafeAlgorithm, PPO): the on-policy family's training step on RLlib's new
API stack (PPO-Lag, P3O, FOCOPS, CUP, RESPO, TRPO-Lag, CPO, PCPO: each names its config class).

The MRO is OnPolicySafeAlgorithm → SafeAlgorithm → PPO → Algorithm: SafeAlgorithm's ``setup``, ``get_metadata``
and ``restore_from_path`` call ``super()``, which PPO does not override, so they wrap
Algorithm's; PPO contributes its config and training step. The training step is RLlib's PPO
step (ppo.py, new stack, env-step counting) with two additions: the costs of the episodes
completed in the batch go to the learner (Ĵ_C, learner.py), and the top-level results
(episode return and cost, ν, feasibility) are logged. One iteration:

  1. sample ``train_batch_size_per_learner`` env steps with the current policy;
  2. one ``learner_group.update``: Ĵ_C (and a multiplier's step), then the cost GAE and
     ``num_epochs`` epochs of minibatches (learner.py);
  3. the new weights (and ν) to the env runners.

OmniSafe and safety-starter-agents reset their envs every epoch, dropping the episode cut at an
epoch's end from Ĵ_C; RLlib's episodes run on across iterations (a cut chunk is bootstrapped with
V(s) at the cut), so every episode counts once, in the iteration it completes.
"""

from __future__ import annotations

from ray.rllib.algorithms.ppo.ppo import PPO
from ray.rllib.core import ALL_MODULES
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    ENV_RUNNER_SAMPLING_TIMER,
    LEARNER_RESULTS,
    LEARNER_UPDATE_TIMER,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
    NUM_MODULE_STEPS_TRAINED_LIFETIME,
    SYNCH_WORKER_WEIGHTS_TIMER,
    TIMERS,
)

from lac_rllib.constrained.algorithm import SafeAlgorithm
from lac_rllib.constrained.costs import completed_constraint_costs, completed_episode_stats
from lac_rllib.constrained.metrics import TS_CONSTRAINT_COSTS, TS_EPISODE_COSTS, TS_ITERATION
from lac_rllib.constrained.minibatch_loop import update_kwargs


class OnPolicySafeAlgorithm(SafeAlgorithm, PPO):
    """Base of the on-policy algorithms; a subclass names its config class (``CONFIG_CLASS``)."""

    @override(PPO)
    def training_step(self) -> None:
        cfg = self.config
        with self.metrics.log_time((TIMERS, ENV_RUNNER_SAMPLING_TIMER)):
            episodes, runner_results = synchronous_parallel_sample(
                worker_set=self.env_runner_group, max_env_steps=cfg.total_train_batch_size,
                sample_timeout_s=cfg.sample_timeout_s, _uses_new_env_runners=True, _return_metrics=True)
            if not episodes:  # every env runner failed
                return
            self.metrics.aggregate(runner_results, key=ENV_RUNNER_RESULTS)
        # Before the update: the learner connector extends every chunk by a phantom step and marks
        # it truncated, so afterwards every chunk would look complete.
        returns, costs = completed_episode_stats(episodes)
        constraint_costs = completed_constraint_costs(episodes)  # several constraints: each episode's K

        # minibatch_size None: full-batch epochs (RLlib then cycles minibatches of the batch's env
        # steps; the fused loop takes plans of a set size only).
        loop = cfg.update_path if cfg.minibatch_size else "rllib"
        passes = update_kwargs(loop, minibatch_size=cfg.minibatch_size, num_epochs=cfg.num_epochs,
                               shuffle=cfg.shuffle_batch_per_epoch)
        with self.metrics.log_time((TIMERS, LEARNER_UPDATE_TIMER)):
            learner_results = self.learner_group.update(
                episodes=episodes,
                timesteps={
                    **passes.pop("timesteps"),
                    NUM_ENV_STEPS_SAMPLED_LIFETIME: self.metrics.peek((ENV_RUNNER_RESULTS,
                                                                       NUM_ENV_STEPS_SAMPLED_LIFETIME)),
                    NUM_MODULE_STEPS_TRAINED_LIFETIME: self.metrics.peek(
                        (LEARNER_RESULTS, ALL_MODULES, NUM_MODULE_STEPS_TRAINED_LIFETIME), default=0),
                    TS_EPISODE_COSTS: costs,
                    **({TS_CONSTRAINT_COSTS: constraint_costs} if constraint_costs else {}),
                    TS_ITERATION: self.iteration,
                },
                **passes,
            )
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)

        with self.metrics.log_time((TIMERS, SYNCH_WORKER_WEIGHTS_TIMER)):
            self.env_runner_group.sync_weights(from_worker_or_learner_group=self.learner_group,
                                               policies=set(learner_results[0].keys()) - {ALL_MODULES},
                                               inference_only=True)
        self.log_top_level(returns, costs, constraint_costs)
