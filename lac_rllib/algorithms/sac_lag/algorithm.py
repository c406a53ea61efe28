"""SACLag(OffPolicySafeAlgorithm): OmniSafe's SACLag on RLlib's new API stack, on LAC's skeleton.

One ``training_step``:
  1. sample ``env_steps_per_iteration`` steps (uniformly random actions while fewer than
     ``random_env_steps`` were sampled [O: start_learning_steps]) into the replay buffer;
  2. once ``random_env_steps`` are reached, one ``learner_group.update`` call of
     ``updates_per_env_step`` × (new env steps) minibatches over the whole buffer, handing the
     learner the costs of the episodes completed in the batch (it keeps the last ``cost_window``
     for Ĵ_C). One call per iteration, not one per minibatch: each call costs ~0.1 s of RLlib's
     machinery (docs/dependencies.md, "Cost of an update call").
"""

from __future__ import annotations

from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.sac_lag.config import SACLagConfig
from lac_rllib.constrained.metrics import NU, TS_CONSTRAINT_COSTS, TS_EPISODE_COSTS
from lac_rllib.constrained.minibatch_loop import update_kwargs
from lac_rllib.families.off_policy.algorithm import OffPolicySafeAlgorithm


class SACLag(OffPolicySafeAlgorithm):
    ALGO, CONFIG_CLASS = "sac_lag", SACLagConfig

    @override(OffPolicySafeAlgorithm)
    def training_step(self) -> None:
        cfg = self.config
        before = self.lifetime_env_steps
        returns, costs = self.sample_into_replay(random_actions=before < cfg.random_env_steps)
        new_steps = self.lifetime_env_steps - before
        updating = self.lifetime_env_steps >= cfg.random_env_steps
        if updating:
            if cfg.minibatch_draws == "with_replacement":
                # The learner connector drew updates_per_iteration minibatches' rows (DrawRows):
                # one pass over them, in order, is that many uniform draws from the buffer.
                plan = {"num_total_minibatches": cfg.updates_per_iteration, "num_epochs": 1, "shuffle": False}
            else:
                # num_epochs > 1 with a reshuffle: RLlib's MiniBatchCyclicIterator then reshuffles the
                # buffer every time the minibatches wrap around it (at one update per env step an
                # iteration draws several times a small buffer's rows); num_total_minibatches sets the steps.
                plan = {"num_total_minibatches": max(1, round(cfg.updates_per_env_step * new_steps)),
                        "num_epochs": 2, "shuffle": True}
            passes = update_kwargs(cfg.update_path, minibatch_size=cfg.batch_size, **plan)
            passes["timesteps"] = {TS_EPISODE_COSTS: list(costs), **passes["timesteps"],
                                   **({TS_CONSTRAINT_COSTS: self.constraint_costs} if self.constraint_costs else {})}
            self.update_from_replay(**passes)
        self.log_top_level(returns, costs, self.constraint_costs)
        if not updating:
            # No learner results yet, so log_top_level found no ν: report λ as the learner holds it
            # (λ₀), so that every row has a finite ν (the largest λ_k with K constraints).
            results = self.learner_group.foreach_learner(
                lambda learner: float(learner.module[DEFAULT_MODULE_ID].nu.max()))
            self.metrics.log_value(NU, next(iter(results)).get(), window=1)
