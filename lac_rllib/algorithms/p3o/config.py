"""P3OConfig: Penalized Proximal Policy Optimization on the on-policy base (no multiplier).

P3O replaces the Lagrange multiplier by an exact penalty (Zhang et al. 2022, eq. 9): the policy
minimises PPO's clipped loss on A^R plus κ·ReLU(mean(r·A^C) + Ĵ_C − b) (learner.py). It has no
multiplier, so its fields are the on-policy family's (:class:`OnPolicyParams`: the critics, the
KL stop, the epochs, the cost window that gives Ĵ_C) with PPO's clip and κ; its rows still
report ``nu``: the penalty's active weight κ·1[penalty > 0] (docs/baselines.md, "P3O").

Source tags: [O] OmniSafe P3O (configs/on-policy/P3O.yaml, algorithms/.../penalty_function/p3o.py),
[D] ours. The defaults are [O]'s (the paper ran OmniSafe's P3O with its defaults, App. D).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.fields import INT_GE_1, NON_NEGATIVE, POSITIVE, one_of, or_none, param
from lac_rllib.constrained.search_space import Searched
from lac_rllib.families.on_policy.config import OMNISAFE_BUDGET, ON_POLICY_PRESETS, OnPolicyConfig, OnPolicyParams

#: The learner's own result keys, beside the on-policy family's (lac_rllib/constrained/metrics.py).
COST_PENALTY = "cost_penalty"  # P3O: κ·ReLU(mean(r·A^C) + Ĵ_C − b), last minibatch

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe")


@dataclasses.dataclass
class P3OParams(OnPolicyParams):
    """The P3O hyperparameters: its preset, PPO's clip and the penalty's κ, after the on-policy
    family's fields (no multiplier)."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D] (see ``PRESETS``)."""

    # --- P3O ---
    kappa: float = param(20.0, accepts=NON_NEGATIVE)
    """κ, the weight of the exact penalty κ·ReLU(mean(r·A^C) + Ĵ_C − b) [O kappa 20]; the penalty is
    exact (its minimiser is the constrained one) once κ exceeds the optimal multiplier (Zhang et
    al. 2022, Thm. 1); 0 switches the constraint off (PPO on A^R)."""
    clip_param: float = param(0.2, accepts=POSITIVE)
    """ε of PPO's clipped surrogate on A^R (RLlib's field) [O clip 0.2]; the cost surrogate is unclipped [O]."""
    num_epochs: int = param(10, accepts=INT_GE_1)
    """Passes over the iteration's batch (RLlib's field) [O P3O.yaml update_iters 10]."""


PRESETS: dict[str, dict[str, Any]] = {
    **ON_POLICY_PRESETS,  # [O] the family's sizes (no multiplier: no faster ν on the tiny task)
    "omnisafe": {"lr_decay_horizon": OMNISAFE_BUDGET},
}


class P3OConfig(OnPolicyConfig):
    """Config for :class:`lac_rllib.algorithms.p3o.algorithm.P3O`; fields: :class:`P3OParams`."""

    SEVERAL_CONSTRAINTS = True  # a penalty per constraint, each on its own cost advantage and limit

    ALGO = "p3o"
    OMNISAFE_NAME = "P3O"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = P3OParams, fields.FieldSet(P3OParams, "P3O"), PRESETS
    SEARCH_SPACE = {
        "lr": OnPolicyConfig.SEARCH_SPACE["lr"],
        "kappa": Searched("loguniform", "Zhang et al. 2022 (P3O) study the penalty factor κ's sensitivity",
                          around=5.0),
        "clip_param": OnPolicyConfig.SEARCH_SPACE["clip_param"],
    }
    REPORTED_KEYS = (*metrics.PPO_LAG_KEYS, COST_PENALTY)
    ALGORITHM_CLASS = "lac_rllib.algorithms.p3o.algorithm.P3O"
    LEARNER_CLASS = "lac_rllib.algorithms.p3o.learner.P3OTorchLearner"
