"""SafeAlgorithm: what every constrained algorithm here does around its own ``training_step``.

- registers its task's env in every Ray process;
- writes the lac-rllib keys into the checkpoint's ``rllib_checkpoint.json`` (version, format,
  algorithm, task, cost convention, config), which ``lac_rllib.evaluation`` checks;
- reseeds a restored run from (seed, iteration) so it does not replay its first iteration;
- reports the top-level result keys of ``lac_rllib.constrained.metrics`` every iteration.
"""

from __future__ import annotations

import importlib.metadata
import json

import numpy as np
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.annotations import override
from ray.rllib.utils.debug import update_global_seed_if_necessary
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, LEARNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.constrained.metrics import (
    COST_LIMIT,
    COST_RATE,
    COST_TOTAL,
    ENV_STEPS,
    EPISODE_COST,
    EPISODE_RETURN,
    EPISODES_THIS_ITER,
    FEASIBLE,
    NU,
    per_constraint,
)
from lac_rllib.constrained.task_config import register_task_env
from lac_rllib.tasks import user as user_tasks

#: Version of the lac-rllib keys in a checkpoint's rllib_checkpoint.json (lac_rllib.evaluation reads
#: this one and format 2). 2: the classes moved to lac_rllib.algorithms / lac_rllib.constrained
#: (0.2.0); 3: the algorithm's fields under ``algo_config`` (format 2 called them ``lac_config``);
#: 4: the on-policy family's module, learner and state on the shared bases of lac_rllib/constrained/
#: (0.3.0: a format-3 PPO-Lag checkpoint names module classes that moved).
CHECKPOINT_FORMAT = 4


def resume_seed(seed: int, iteration: int) -> int:
    """The seed of a run restored at ``iteration`` (see SafeAlgorithm._reseed_for_restore): a hash of
    both, below 2**31 with room for RLlib's + worker index, so (seed, iteration) pairs do not share streams."""
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1)[0]) % (2**31 - 2**16)


class SafeAlgorithm(Algorithm):
    """Base of the constrained algorithms; a subclass names its config class in ``CONFIG_CLASS``
    (which names the algorithm: ``ALGO``) and implements ``training_step``, calling
    :meth:`log_top_level` at its end."""

    #: Its config class (a SafeTaskConfig), which RLlib's ``get_default_config`` builds for it.
    CONFIG_CLASS: type | None = None

    @classmethod
    @override(Algorithm)
    def get_default_config(cls):
        return cls.CONFIG_CLASS(cls)

    @override(Algorithm)
    def setup(self, config) -> None:
        if config.task_id:
            register_task_env(config.task_spec)
        super().setup(config)
        self._last_episode_stats = (float("nan"), float("nan"))
        #: With several constraints: each constraint's mean cost over the last iteration that
        #: completed an episode (NaN before one did).
        self._last_constraint_costs = [float("nan")] * config.num_constraints

    @override(Algorithm)
    def get_metadata(self) -> dict:
        """RLlib writes this into the checkpoint's ``rllib_checkpoint.json``; lac_rllib.evaluation
        checks the version and format and reads the task and config."""
        cfg = self.config
        ours = {
            "lac_rllib_version": importlib.metadata.version("lac-rllib"),
            "checkpoint_format": CHECKPOINT_FORMAT,
            "algo": cfg.ALGO,  # the config's name: a user's config on a package algorithm names itself
            "task_id": cfg.task_id,
            "seed": cfg.seed,
            "cost_limit": cfg.effective_cost_limit,
            "episode_cost_discount": cfg.effective_episode_cost_discount,
            "algo_config": cfg.params(),  # the algorithm's fields
            # The env as trained (its backend, a Point task's robot): the evaluation builds it again.
            "env_config": dict(cfg.env_config or {}),
            "resolved": cfg.resolved(),  # what rule-valued fields ("auto") ran as on the learner's machine
        }
        if cfg.task_spec is not None and cfg.task_spec.factory == user_tasks.FACTORY:
            ours["task_definition"] = user_tasks.definition(cfg.task_spec)  # restorable where it is not registered
        # JSON-safe (tuples -> lists, anything exotic -> str).
        return {**super().get_metadata(), **json.loads(json.dumps(ours, default=str))}

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
            # RLlib's SingleAgentEnvRunner seeds its envs with its private ``_seed`` at the reset
            # that ``_needs_initial_reset`` asks for, and has no public way to reseed
            # (docs/dependencies.md; tests/constrained/test_safe_algorithm.py breaks if that changes).
            # Every runner gets seed + worker index, as at construction.
            runner._seed = seed + (runner.worker_index or 0)
            runner._needs_initial_reset = True
            update_global_seed_if_necessary(runner.config.framework_str, runner._seed)

        self.env_runner_group.foreach_env_runner(reseed, local_env_runner=True)
        self.learner_group.foreach_learner(lambda learner: update_global_seed_if_necessary("torch", seed))

    def log_top_level(self, returns: list[float], costs: list[float], constraint_costs=()) -> None:
        """episode_return / episode_cost: means over the episodes completed this iteration
        (the last known values carry over an iteration in which none completed); ν is the
        default module's, as its learner logged it. With several constraints (``constraint_costs``:
        each completed episode's K costs), also each constraint's cost and limit
        (``episode_cost/NAME``, ``cost_limit/NAME``), and ``feasible`` is every constraint within
        its limit: episode_cost is then the summed cost ``info["cost"]``, cost_limit the limits' sum."""
        if returns:
            self._last_episode_stats = (float(np.mean(returns)), float(np.mean(costs)))
        if len(constraint_costs):
            self._last_constraint_costs = np.mean(constraint_costs, axis=0).tolist()
        ret, cost = self._last_episode_stats
        limit = self.config.effective_cost_limit
        several = self.config.several_constraints
        if several is not None:
            for name, c, b in zip(several.names, self._last_constraint_costs, several.limits):
                self.metrics.log_value(per_constraint(EPISODE_COST, name), c, window=1)
                self.metrics.log_value(per_constraint(COST_LIMIT, name), b, window=1)
            within = float(all(c <= b for c, b in zip(self._last_constraint_costs, several.limits)))
        else:
            within = float(cost <= limit)
        nu = self.metrics.peek((LEARNER_RESULTS, DEFAULT_MODULE_ID, NU), default=float("nan"))
        steps = self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
        # The training's cost so far, a lifetime sum in RLlib's metrics (checkpointed with them).
        self.metrics.log_value(COST_TOTAL, float(sum(costs)), reduce="lifetime_sum")
        total = self.metrics.peek(COST_TOTAL, default=0.0)
        for key, value in {
            EPISODE_RETURN: ret, EPISODE_COST: cost, COST_LIMIT: limit,
            FEASIBLE: within, NU: float(nu), EPISODES_THIS_ITER: len(returns),
            ENV_STEPS: steps, COST_RATE: float(total) / steps if steps else float("nan"),
        }.items():
            self.metrics.log_value(key, value, window=1)
