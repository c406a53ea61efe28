"""CPOConfig: Constrained Policy Optimization (Achiam et al. 2017) on the trust-region base.

CPO takes the family's step (the whole batch, conjugate gradient, the line search) without a
multiplier: the step solves the linearised problem max gᵀΔ s.t. bᵀΔ + c ≤ 0, ½ΔᵀHΔ ≤ δ in closed
form from its dual, recovering along −H⁻¹b when no feasible point is in reach (learner.py;
families/trust_region/step.py ``cpo_step``). :class:`CostStepParams` are the fields PCPO shares.

Source tags: [O] OmniSafe CPO (configs/on-policy/CPO.yaml, second_order/cpo.py), [S]
safety-starter-agents CPO (pg/agents.py ``CPOAgent``: the paper's CPO, App. D), [D] ours. The
defaults are [O]'s; the ``ssa`` preset is [S]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.constrained import fields
from lac_rllib.constrained.fields import INT_GE_1, one_of, or_none, param
from lac_rllib.constrained.search_space import lr
from lac_rllib.families.trust_region.config import (
    OMNISAFE_STEP,
    SSA_TRUST_REGION,
    TRUST_REGION_KEYS,
    TRUST_REGION_PRESETS,
    TrustRegionConfig,
    TrustRegionParams,
)

#: The learner's own result keys, beside the on-policy family's (lac_rllib/constrained/metrics.py).
COST_GAP = "cost_gap"  # CPO, PCPO: c = Ĵ_C − b as the step used it (cost_gap_scale); NaN: no episode yet
CPO_CASE = "cpo_case"  # CPO: the case of its step, 0-4 (OmniSafe's numbering: 3-4 TRPO, 1-2 dual, 0 recovery)

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe", "ssa")
COST_GAP_SCALES = ("none", "episode_length")
DUAL_CONVENTIONS = ("paper", "omnisafe")


@dataclasses.dataclass
class CostStepParams(TrustRegionParams):
    """The fields of the trust-region steps that read the cost gap (CPO, PCPO), after the family's."""

    # --- cost gap ---
    cost_gap_scale: str = param("none", accepts=one_of(COST_GAP_SCALES))
    """The units of c = Ĵ_C − b in the linearised constraint c + bᵀΔ ≤ 0, b the gradient of the
    per-step cost surrogate mean(r·A^C): "none", the episode cost's own [O cpo.py:391]; or
    "episode_length", divided by the mean length of the episodes Ĵ_C is taken over [S agents.py:
    ``c /= rescale``], the per-step units of bᵀΔ. ~1000× apart on 1000-step tasks, which decides
    the case (docs/baselines.md, "TRPO-Lagrangian, CPO and PCPO")."""


@dataclasses.dataclass
class CPOParams(CostStepParams):
    """The CPO hyperparameters: its preset, the dual's convention and the line search's length,
    after the cost-gap and trust-region fields (no multiplier)."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D], "ssa" [S]
    (see ``PRESETS``)."""

    # --- CPO ---
    dual_convention: str = param("paper", accepts=one_of(DUAL_CONVENTIONS))
    """The closed-form dual of cases 1-2: "paper", Achiam et al.'s App. 10.2 with r = gᵀH⁻¹b
    taken in its minimising sign [S agents.py]; "omnisafe", [O cpo.py:291-326]'s, which puts the
    ascent-form r into those formulas (a sign error: its ν* is not the problem's); the ``omnisafe``
    preset takes it (tests/algorithms/cpo/test_cpo_golden.py: [O]'s λ* < 0 in case 2 there)."""
    backtrack_iters: int = param(20, accepts=INT_GE_1)
    """Fractions 1, c, c², … of the step the line search tries before it keeps θ_old [O
    _update_actor: total_steps=20; S backtrack_iters 10]."""


#: [S] CPO as the paper ran it: the family's ssa values and c divided by the mean episode length.
SSA = {**SSA_TRUST_REGION, "cost_gap_scale": "episode_length"}
PRESETS: dict[str, dict[str, Any]] = {
    **TRUST_REGION_PRESETS,  # [O] CPO.yaml is the defaults; the family's tiny sizes [D]
    # [O]'s own step: its KL (so its damping) and its dual (tests/algorithms/cpo/test_cpo_golden.py).
    "omnisafe": {**OMNISAFE_STEP, "dual_convention": "omnisafe"},
    "ssa": SSA,
}


class CPOConfig(TrustRegionConfig):
    """Config for :class:`lac_rllib.algorithms.cpo.algorithm.CPO`; fields: :class:`CPOParams`."""

    # K constraints: CPO's step with a dual variable each, PCPO's projection onto their intersection
    # (lac_rllib/families/trust_region/multi_constraint.py).
    SEVERAL_CONSTRAINTS = True

    ALGO = "cpo"
    OMNISAFE_NAME = "CPO"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = CPOParams, fields.FieldSet(CPOParams, "CPO"), PRESETS
    SEARCH_SPACE = {
        **TrustRegionConfig.SEARCH_SPACE,
        "critic_lr": lr("[O] the critics' lr (CPO's cost critic sets its recovery steps)"),
    }
    REPORTED_KEYS = (*TRUST_REGION_KEYS, COST_GAP, CPO_CASE)
    ALGORITHM_CLASS = "lac_rllib.algorithms.cpo.algorithm.CPO"
    LEARNER_CLASS = "lac_rllib.algorithms.cpo.learner.CPOTorchLearner"
