"""CUPConfig: Constrained Update Projection = PPO-Lag + a projection stage.

CUP (Yang et al. 2022) updates the policy in two stages per iteration (its Algorithm 1): a policy
improvement on the reward alone, PPO's clipped surrogate on A^R, then a projection back towards
the constraint, a first-order minimisation of the cost surrogate plus the KL to the improved
policy (learner.py). Everything else is PPO-Lag's: the module (π, V_R, V_C, ν), the cost GAE,
ν's Adam step, the KL early stop, the minibatch epochs, the training step.

Source tags: [O] OmniSafe CUP (configs/on-policy/CUP.yaml, algorithms/on_policy/first_order/cup.py;
the paper ran it with these defaults, its App. D), [D] ours. CUP.yaml is PPOLag.yaml but for
target_kl and the multiplier's upper bound, so the family's defaults are [O]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.algorithms.ppo_lag import config as ppo_lag
from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.fields import INT_GE_1, POSITIVE, one_of, or_none, param
from lac_rllib.constrained.search_space import Searched
from lac_rllib.families.on_policy.config import OMNISAFE_BUDGET, OnPolicyLagParams

#: The learner's own result keys, beside the on-policy family's (lac_rllib/constrained/metrics.py).
PROJECTION_LOSS = "projection_loss"  # CUP: stage 2's loss, last minibatch
PROJECTION_EPOCHS = "projection_epochs"  # CUP: epochs stage 2 trained before its KL stop
PROJECTION_KL = "projection_kl"  # CUP: KL(π_stage1 ‖ π) over the batch at stage 2's last check

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe")


@dataclasses.dataclass
class CUPParams(OnPolicyLagParams):
    """The CUP hyperparameters: its preset, stage 1's clip, the stages' KL stop, the projection's
    epochs and the multiplier's bound, after the on-policy Lagrangian family's fields."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D] (see
    ``PRESETS``). No "paper" preset: the paper ran OmniSafe's CUP with its defaults."""

    # --- CUP ---
    clip_param: float = param(0.2, accepts=POSITIVE)
    """ε of stage 1's clipped surrogate (RLlib's field; its default is 0.3) [O clip 0.2]."""
    projection_epochs: int | None = param(None, accepts=or_none(INT_GE_1))
    """Epochs of stage 2 (the projection) over the iteration's batch, after stage 1's num_epochs
    [O update_iters: both stages]; None = num_epochs."""
    target_kl: float | None = param(0.01, accepts=or_none(POSITIVE))
    """KL early stop of both stages [O target_kl 0.01, kl_early_stop]: stage 1 stops once
    KL(π_old ‖ π) over the batch after an epoch exceeds it (PPO-Lag's stop; see kl_stop_late),
    stage 2 once KL(π_stage1 ‖ π) does; None = off."""
    nu_max: float | None = param(2.0, accepts=or_none(POSITIVE))
    """ν is held in [0, nu_max] after each step [O lagrangian_upper_bound 2.0]; None = no upper bound."""


PRESETS: dict[str, dict[str, Any]] = {
    **{name: dict(values) for name, values in ppo_lag.PRESETS.items() if name != "ssa"},  # [O] as PPO-Lag's
    # [D] PPO-Lag's tiny sizes and its KL stop of 0.02: at [O]'s 0.01 the tiny lr (1e-3) ends stage 1
    # after its first epoch in most iterations, and 40k steps end at a random policy's return (−10,
    # seed 0); at 0.02 the last 5 iterations' mean return is −0.3 at cost 0.5 (limit 2), as PPO-Lag's.
    "tiny": {**ppo_lag.PRESETS["tiny"], "target_kl": 0.02},
    "omnisafe": {"lr_decay_horizon": OMNISAFE_BUDGET},
}


class CUPConfig(PPOLagConfig):
    """Config for :class:`lac_rllib.algorithms.cup.algorithm.CUP`; fields: :class:`CUPParams`."""

    ALGO = "cup"
    OMNISAFE_NAME = "CUP"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = CUPParams, fields.FieldSet(CUPParams, "CUP"), PRESETS
    SEARCH_SPACE = {
        **PPOLagConfig.SEARCH_SPACE,
        "target_kl": Searched("loguniform", "[O] its projection's KL bound, 0.01 or 0.02 across presets",
                              around=3.0),
    }
    REPORTED_KEYS = (*metrics.PPO_LAG_KEYS, PROJECTION_LOSS, PROJECTION_EPOCHS, PROJECTION_KL)
    ALGORITHM_CLASS = "lac_rllib.algorithms.cup.algorithm.CUP"
    LEARNER_CLASS = "lac_rllib.algorithms.cup.learner.CUPTorchLearner"

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """Update seconds per env step on one CPU beyond sampling: PPO-Lag's, doubled for stage 2's
        epochs (an upper estimate, not measured: stage 2 steps the policy only)."""
        return 2.0 * PPOLagConfig.plan_update_s(params, preset)

    @property
    def stage2_epochs(self) -> int:
        """The projection's epochs: projection_epochs, else num_epochs [O update_iters]."""
        return int(self.num_epochs if self.projection_epochs is None else self.projection_epochs)
