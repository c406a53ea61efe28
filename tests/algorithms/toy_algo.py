"""A throwaway algorithm of the tests' own, as a user writes one (docs/baselines.md, "Your own
algorithm"): a config class and its learner, nothing else. PPO-Lag's pieces with a field and sizes
of its own, named by its import path (``tests.algorithms.toy_algo``: a config class names itself by
its module). No file of the package knows it: the tests prove a user's algorithm runs through the
plan, the sweep, MLflow, the report and lac-eval by the registry alone.

Its own field ``toy_marker`` changes nothing it learns; its learner reports it back every
iteration under its own key (``REPORTED_KEYS``), so a row shows the field reached the learner.
At the smoke budget it runs smaller than PPO-Lag's smoke (its own ``BUDGET_FIELDS``).
"""

from __future__ import annotations

import dataclasses

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig, PPOLagParams
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.fields import POSITIVE, FieldSet, param

TOY_MARKER = "toy_marker"  # its own field, and the key its learner reports it under


@dataclasses.dataclass
class ToyParams(PPOLagParams):
    """PPO-Lag's fields and one of the toy's own."""

    toy_marker: float = param(1.0, accepts=POSITIVE)
    """A number the learner reports back every iteration (it changes nothing the toy learns)."""


class ToyLearner(PPOLagTorchLearner):
    def after_gradient_based_update(self, *, timesteps) -> None:
        super().after_gradient_based_update(timesteps=timesteps)
        for mid in self.module.keys():
            marker = float(self.config.get_config_for_module(mid).toy_marker)
            self.metrics.log_value((mid, TOY_MARKER), marker, window=1)


class ToyConfig(PPOLagConfig):
    """PPO-Lag's config with the toy's fields, learner and smoke sizes (its own, smaller than
    PPO-Lag's: 400-step iterations, 16-wide networks, 1 epoch); all else is PPO-Lag's."""

    PARAMS, FIELDS = ToyParams, FieldSet(ToyParams, "Toy")
    REPORTED_KEYS = (*PPOLagConfig.REPORTED_KEYS, TOY_MARKER)
    LEARNER_CLASS = f"{__name__}.ToyLearner"
    BUDGET_FIELDS = {"smoke": {"*": {"train_batch_size_per_learner": 400, "minibatch_size": 100, "num_epochs": 1,
                                     "hidden": (16, 16), "num_envs_per_env_runner": 1}}}
