"""ActorCriticRLModule: the RLlib side of a module whose actor acts on the env runners and whose
critics (and actor, where the algorithm has a target actor) have Polyak copies on the learner.

A subclass builds its networks in ``setup``, the acting one as ``actor`` (``actor(obs)`` → the
mean and log σ of its action distribution), names each network with a target in ``TARGETS``
(online attribute → target attribute, in the order the Polyak update walks them) and writes its
own ``_forward_train`` and ``forward_target``. Those networks but the actor, and their targets,
are non-inference attributes: the env runners hold the actor (and the module's buffers) only.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.utils import make_target_network
from ray.rllib.core.rl_module.apis import InferenceOnlyAPI, TargetNetworkAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from ray.rllib.utils.annotations import override


class ActorCriticRLModule(TorchRLModule, InferenceOnlyAPI, TargetNetworkAPI):
    framework = "torch"
    #: Online network attribute → its Polyak target's attribute (made by RLlib's make_target_network).
    TARGETS: dict[str, str] = {}

    # ----- acting (env runners) -----
    @override(TorchRLModule)
    def _forward_inference(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        mean, log_std = self.actor(batch[Columns.OBS])
        return {Columns.ACTION_DIST_INPUTS: torch.cat([mean, log_std], dim=-1)}

    @override(TorchRLModule)
    def _forward_exploration(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        return self._forward_inference(batch)

    # ----- RLlib APIs -----
    @override(TargetNetworkAPI)
    def make_target_networks(self) -> None:
        for online, target in self.TARGETS.items():
            setattr(self, target, make_target_network(getattr(self, online)))

    @override(TargetNetworkAPI)
    def get_target_network_pairs(self):
        return [(getattr(self, online), getattr(self, target)) for online, target in self.TARGETS.items()]

    @override(InferenceOnlyAPI)
    def get_non_inference_attributes(self) -> list[str]:
        return [online for online in self.TARGETS if online != "actor"] + list(self.TARGETS.values())
