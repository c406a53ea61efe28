"""CUP(PPOLag): PPO-Lag's training step (sample, one learner update, sync) with CUP's learner.

Both stages run inside that one ``learner_group.update``: the learner adds the projection's epochs
to the epochs the step asks for (learner.py, ``CUPTorchLearner.update``). A second update call
would rerun the learner connector and recompute A^C with the V_C stage 1 stepped; OmniSafe's
stage 2 reads the same stored batch again (``self._buf.get()``, cup.py ``_update``).
"""

from __future__ import annotations

from lac_rllib.algorithms.cup.config import CUPConfig
from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag


class CUP(PPOLag):
    CONFIG_CLASS = CUPConfig
