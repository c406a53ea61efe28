"""RESPOTorchRLModule: the on-policy module (π, V_R, V_C, ν) plus the reach critic V_p.

``reach_vf`` is V_p(s) ∈ (0, 1), the estimated (discounted) probability that the policy reaches a
state of positive cost from s: an MLP of the other critics' shape with a sigmoid head [G
core_respo.py: ``self.vp = MLPCritic(..., nn.Sigmoid)``]. Like the other critics it is a
non-inference attribute: it exists on the learner only, not on the env runners. With K constraints
(``num_constraints``) K of them, one per constraint: V_p(s) is then (B, K).
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.utils.annotations import override

from lac_rllib.families.on_policy.module import CostCritic, CostCritics, OnPolicyTorchRLModule


class ReachCritic(CostCritic):
    """V_p(s): V_C's MLP and linear head, then a sigmoid [G]."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(super().forward(obs))


class ReachCritics(CostCritics):
    """K reach critics V_pk(s), one per constraint: (B, K)."""

    def __init__(self, catalog, k: int):
        torch.nn.Module.__init__(self)
        self.critics = torch.nn.ModuleList(ReachCritic(catalog) for _ in range(k))


class RESPOTorchRLModule(OnPolicyTorchRLModule):
    @override(OnPolicyTorchRLModule)
    def setup(self):
        super().setup()
        k = int(self.model_config.get("num_constraints", 1))
        # deleted again on env runners (inference-only)
        self.reach_vf = ReachCritic(self.catalog) if k == 1 else ReachCritics(self.catalog, k)

    def compute_reach_probs(self, batch: dict[str, Any]) -> torch.Tensor:
        """V_p(s) of every row of ``batch``: (B,), (B, K) with K constraints."""
        return self.reach_vf(batch[Columns.OBS])

    @override(OnPolicyTorchRLModule)
    def get_non_inference_attributes(self) -> list[str]:
        return [*super().get_non_inference_attributes(), "reach_vf"]
