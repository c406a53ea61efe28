"""TRPOLagConfig: TRPO-Lagrangian = the trust-region base (families/trust_region/config.py) + the
Lagrange multiplier. Source tags: [O] OmniSafe TRPOLag (configs/on-policy/TRPOLag.yaml,
naive_lagrange/trpo_lag.py), [S] safety-starter-agents TRPO-L (pg/run_agent.py: the paper's TRPO-L,
App. D), [D] ours. The defaults are [O]'s; the ``ssa`` preset is [S]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.constrained import fields
from lac_rllib.constrained.fields import one_of, or_none, param
from lac_rllib.constrained.search_space import MULTIPLIER_LR, lr
from lac_rllib.families.on_policy.config import OnPolicyLagParams
from lac_rllib.families.trust_region.config import (
    SSA_TRUST_REGION,
    TRUST_REGION_PRESETS,
    TrustRegionConfig,
    TrustRegionParams,
)

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe", "ssa")


@dataclasses.dataclass
class TRPOLagParams(TrustRegionParams, OnPolicyLagParams):
    """The TRPO-Lag hyperparameters: its preset, after the trust-region family's fields and the
    multiplier's (PPO-Lag's, [O]'s defaults: ν₀ 0.001, Adam at 0.035, TRPOLag.yaml)."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D], "ssa" [S]
    (see ``PRESETS``)."""


PRESETS: dict[str, dict[str, Any]] = {
    **TRUST_REGION_PRESETS,
    "tiny": {**TRUST_REGION_PRESETS["tiny"], "lagrangian_lr": 0.1},  # and PPO-Lag's faster ν
    # ν = softplus(p) from 1, Adam at 0.05 on this epoch's mean cost [S run_agent.py penalty_*].
    "ssa": {**SSA_TRUST_REGION, "nu_init": 1.0, "lagrangian_lr": 0.05, "nu_parametrization": "softplus"},
}


class TRPOLagConfig(TrustRegionConfig):
    """Config for :class:`lac_rllib.algorithms.trpo_lag.algorithm.TRPOLag`; fields: :class:`TRPOLagParams`."""

    SEVERAL_CONSTRAINTS = True  # the same multipliers and advantage (families/on_policy/lagrangian.py)

    ALGO = "trpo_lag"
    OMNISAFE_NAME = "TRPOLag"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = TRPOLagParams, fields.FieldSet(TRPOLagParams, "TRPO-Lag"), PRESETS
    SEARCH_SPACE = {
        "target_kl": TrustRegionConfig.SEARCH_SPACE["target_kl"],
        "cg_damping": TrustRegionConfig.SEARCH_SPACE["cg_damping"],
        "lagrangian_lr": lr(MULTIPLIER_LR),
        "critic_lr": TrustRegionConfig.SEARCH_SPACE["critic_lr"],
    }
    ALGORITHM_CLASS = "lac_rllib.algorithms.trpo_lag.algorithm.TRPOLag"
    LEARNER_CLASS = "lac_rllib.algorithms.trpo_lag.learner.TRPOLagTorchLearner"
