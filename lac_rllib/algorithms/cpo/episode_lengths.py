"""EpisodeLengths: the learner connector that records how long the batch's completed episodes were
(CPO's and PCPO's ``cost_gap_scale="episode_length"``: lac_rllib/algorithms/cpo/learner.py)."""

from __future__ import annotations

from typing import Any

from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.utils.annotations import override


class EpisodeLengths(ConnectorV2):
    """``lengths``: the env steps of each episode that ended in the last batch. Placed first in the
    learner pipeline, before RLlib appends its phantom step and marks every chunk truncated; an
    episode's last chunk ends at its length (``SingleAgentEpisode.t``, counted from its reset)."""

    def __init__(self, input_observation_space=None, input_action_space=None, **kwargs):
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.lengths: list[int] = []

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        self.lengths = [int(e.t) for e in self.single_agent_episode_iterator(episodes, agents_that_stepped_only=False)
                        if e.is_done]
        return batch
