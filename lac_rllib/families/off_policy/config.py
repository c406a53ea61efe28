"""OffPolicyConfig: the config of an OffPolicySafeAlgorithm (lac_rllib/families/off_policy/algorithm.py),
which samples ``env_steps_per_iteration`` env steps into a replay buffer each iteration and trains
on minibatches cut from the whole buffer in one update call.

What it adds to :class:`~lac_rllib.constrained.task_config.SafeTaskConfig`: the iteration's env
steps split over the env runners, and a learner pipeline that gives each row its next observation
and its cost, then orders (or draws) the rows the minibatches are cut from.
"""

from __future__ import annotations

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.connectors.common.batch_individual_items import BatchIndividualItems
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.connectors.learner import (
    AddNextObservationsFromEpisodesToTrainBatch,
    AddObservationsFromEpisodesToBatch,
)
from ray.rllib.utils.annotations import override

from lac_rllib.constrained.costs import AddCostsFromInfos, ShuffleRows
from lac_rllib.constrained.task_config import SafeTaskConfig


class OffPolicyConfig(SafeTaskConfig):
    """Mixed into an ``AlgorithmConfig`` subclass (before it). The algorithm's params have
    ``env_steps_per_iteration``, ``num_envs_per_env_runner``, ``replay_capacity``,
    ``store_replay_buffer`` and the minibatch size, named by ``MINIBATCH_FIELD``."""

    #: The field that holds the minibatch size; RLlib's ``train_batch_size_per_learner`` follows it.
    MINIBATCH_FIELD = ""

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
        self.train_batch_size_per_learner = getattr(self, self.MINIBATCH_FIELD)
        self.rollout_fragment_length = "auto"

    @override(AlgorithmConfig)
    def training(self, **kwargs):
        super().training(**kwargs)
        if self.MINIBATCH_FIELD in kwargs:
            self.train_batch_size_per_learner = getattr(self, self.MINIBATCH_FIELD)
        return self

    @override(AlgorithmConfig)
    def get_rollout_fragment_length(self, worker_index: int = 0) -> int:
        # "auto" splits env_steps_per_iteration (not the minibatch size) over the runners' envs.
        if self.rollout_fragment_length != "auto":
            return self.rollout_fragment_length
        n = self.num_envs_per_env_runner * (self.num_env_runners or 1)
        base, extra = divmod(self.env_steps_per_iteration, n)
        idx = max(worker_index - 1, 0)
        return max(1, base + (1 if idx * self.num_envs_per_env_runner < extra else 0))

    @property
    @override(AlgorithmConfig)
    def _model_config_auto_includes(self) -> dict:
        # Several constraints: the module builds a cost critic group and a ν per constraint.
        k = self.num_constraints
        return {**super()._model_config_auto_includes, **({"num_constraints": k} if k > 1 else {}),
                **self.nu_fixed_model_config()}

    def minibatch_rows(self) -> ConnectorV2:
        """The learner connector piece that orders the buffer's rows for the iteration's minibatches:
        a shuffle (one pass over the buffer per iteration would otherwise cut consecutive steps
        into each minibatch, docs/spec.md §5); an algorithm may draw them instead."""
        return ShuffleRows(seed=self.seed)

    @override(AlgorithmConfig)
    def build_learner_connector(self, input_observation_space, input_action_space, device=None):
        """RLlib's learner pipeline plus s' for the critic targets (as RLlib's SAC adds it), then
        the cost of each row right after s' (docs/dependencies.md, "The cost column": this order),
        then :meth:`minibatch_rows` once the rows are batched."""
        pipeline = super().build_learner_connector(
            input_observation_space=input_observation_space, input_action_space=input_action_space, device=device)
        pipeline.insert_after(AddObservationsFromEpisodesToBatch, AddNextObservationsFromEpisodesToTrainBatch())
        pipeline.insert_after(AddNextObservationsFromEpisodesToTrainBatch,
                              AddCostsFromInfos(constraints=self.constraints_data()))
        pipeline.insert_after(BatchIndividualItems, self.minibatch_rows())
        return pipeline
