"""OnPolicyTorchRLModule: the on-policy family's module, RLlib's default PPO networks plus a cost
critic and the multiplier ν (0 for ever in the algorithms without one: P3O, CPO, PCPO).

- ``encoder.actor_encoder`` + ``pi``: the Gaussian policy, an MLP (``fcnet_hiddens``,
  ``fcnet_activation``) to the mean and a state-independent log σ (``free_log_std``) [O, S];
- ``encoder.critic_encoder`` + ``vf``: the reward critic V_R, a separate MLP of the same shape
  (``vf_share_layers=False``) [O, S];
- ``cost_vf``: the cost critic V_C, a third MLP of that shape, built by the same RLlib catalog;
  with K > 1 constraints (``num_constraints``), K of them, V_C(s) then (B, K) [as OmniSafe keeps a
  cost critic per cost; Kim et al. 2024 a cost value head per constraint];
- ``nu``: the Lagrange multiplier ν, a buffer (it travels with the weights into checkpoints and
  to the env runners), (K,) with K constraints. Only a learner's ``LagrangeMultiplier`` writes it
  (lagrangian.py).

Only the policy (and ν) exist on env runners: both critics are non-inference attributes.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
from ray.rllib.core.columns import Columns
from ray.rllib.core.models.base import ENCODER_OUT
from ray.rllib.utils.annotations import override

from lac_rllib.constrained.lagrange import initial_nus


class CostCritic(torch.nn.Module):
    """V_C(s): an MLP encoder and a linear head, the same shapes as RLlib's reward critic."""

    def __init__(self, catalog):
        super().__init__()
        self.encoder = catalog.actor_critic_encoder_config.base_encoder_config.build(framework="torch")
        self.head = catalog.build_vf_head(framework="torch")

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.encoder({Columns.OBS: obs})[ENCODER_OUT]).squeeze(-1)


class CostCritics(torch.nn.Module):
    """K cost critics V_Ck(s), one per constraint, each a :class:`CostCritic`: (B, K)."""

    def __init__(self, catalog, k: int):
        super().__init__()
        self.critics = torch.nn.ModuleList(CostCritic(catalog) for _ in range(k))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.stack([critic(obs) for critic in self.critics], dim=-1)


class OnPolicyTorchRLModule(DefaultPPOTorchRLModule):
    @override(DefaultPPOTorchRLModule)
    def setup(self):
        super().setup()
        cfg = self.model_config
        if cfg.get("vf_share_layers"):
            raise ValueError("the on-policy family needs separate networks (vf_share_layers=False): one optimizer "
                             "per network")
        k = int(cfg.get("num_constraints", 1))
        self.register_buffer("nu", initial_nus(cfg, k))
        with torch.no_grad():  # RLlib starts the free log σ at 0 [O]; [S] at −0.5
            self.pi.log_std.fill_(float(cfg["log_std_init"]))
        # deleted again on env runners (inference-only)
        self.cost_vf = CostCritic(self.catalog) if k == 1 else CostCritics(self.catalog, k)

    def compute_cost_values(self, batch: dict[str, Any]) -> torch.Tensor:
        """V_C(s) of every row of ``batch``: (B,), (B, K) with K constraints."""
        return self.cost_vf(batch[Columns.OBS])

    def action_dist_inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """π's distribution inputs [mean, log σ] at ``obs`` through the policy network only."""
        return self.pi(self.encoder.actor_encoder({Columns.OBS: obs})[ENCODER_OUT])

    @torch.no_grad()
    def deterministic_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The mean action at ``obs`` (B, obs_dim), as the env receives it: with RLlib's
        ``normalize_actions`` the policy acts in [-1, 1] and the env runner maps that onto the
        action bounds and clips to them (RLlib's ``unsquash_action``); the same here."""
        mean = self.action_dist_inputs(obs)[..., : self.action_space.shape[0]]
        if not self.model_config.get("normalize_actions", True):
            return mean
        low = torch.as_tensor(self.action_space.low, dtype=mean.dtype)
        high = torch.as_tensor(self.action_space.high, dtype=mean.dtype)
        return torch.clamp(low + (mean + 1.0) * (high - low) / 2.0, low, high)

    @override(DefaultPPOTorchRLModule)
    def get_non_inference_attributes(self) -> list[str]:
        return [*super().get_non_inference_attributes(), "cost_vf"]
