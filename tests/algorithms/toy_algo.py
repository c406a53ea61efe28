"""A throwaway algorithm of the tests' own: PPO-Lag's pieces under another name, with a field and
sizes of its own, named by its import path (``tests.algorithms.toy_algo``) as a user names theirs
(docs/baselines.md, "Your own algorithm"). No file of the package knows it: the tests prove a
user's algorithm runs through the plan, the sweep, MLflow, the report and lac-eval by the
registry alone.

Its own field ``toy_marker`` changes nothing it learns; its learner reports it back every
iteration under its own key (``REPORTED_KEYS``), so a row shows the field reached the learner.
At the smoke budget it runs smaller than PPO-Lag's smoke (its own ``BUDGET_FIELDS``).
"""

from __future__ import annotations

import dataclasses

from lac_rllib.algorithms.ppo_lag import config as ppo_lag
from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.fields import POSITIVE, FieldSet, param

TOY_MARKER = "toy_marker"  # its own field, and the key its learner reports it under


@dataclasses.dataclass
class ToyParams(ppo_lag.PPOLagParams):
    """PPO-Lag's fields and one of the toy's own."""

    toy_marker: float = param(1.0, accepts=POSITIVE)
    """A number the learner reports back every iteration (it changes nothing the toy learns)."""


FIELDS = FieldSet(ToyParams, "Toy")


class ToyLearner(PPOLagTorchLearner):
    def after_gradient_based_update(self, *, timesteps) -> None:
        super().after_gradient_based_update(timesteps=timesteps)
        for mid in self.module.keys():
            marker = float(self.config.get_config_for_module(mid).toy_marker)
            self.metrics.log_value((mid, TOY_MARKER), marker, window=1)


class ToyConfig(ppo_lag.PPOLagConfig):
    """PPO-Lag's config with the toy's fields and classes: the shared layer (SafeTaskConfig) sets,
    checks and validates every field of ``PARAMS``, the toy's own included."""

    PARAMS, FIELDS = ToyParams, FIELDS
    REPORTED_KEYS = (*ppo_lag.PPOLagConfig.REPORTED_KEYS, TOY_MARKER)
    ALGORITHM_CLASS = f"{__name__}.ToyAlgo"
    LEARNER_CLASS = f"{__name__}.ToyLearner"


class ToyAlgo(PPOLag):
    ALGO = __name__  # its import path: what runs and checkpoints name it by
    CONFIG_CLASS = ToyConfig


CONFIG_CLASS, PARAMS, PRESETS = ToyConfig, ToyParams, ppo_lag.PRESETS
ACTIONS = ("generator",)  # SPEED_FIELDS, plan_update_s, ...: PPO-Lag's, the algorithm it extends (registry.declared)
#: Its own smoke sizes, smaller than PPO-Lag's (500-step iterations, 32-wide networks, 2 epochs).
BUDGET_FIELDS = {"smoke": {"*": {"train_batch_size_per_learner": 400, "minibatch_size": 100, "num_epochs": 1,
                                 "hidden": (16, 16), "num_envs_per_env_runner": 1}}}
