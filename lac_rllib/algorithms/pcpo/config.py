"""PCPOConfig: Projection-based Constrained Policy Optimization (Yang et al. 2020) on CPO's house.

PCPO takes the reward's TRPO step and projects it onto the linearised cost constraint's
half-space (its eq. 7; learner.py, families/trust_region/step.py ``pcpo_step``), with CPO's
quantities (g, b, H⁻¹g, H⁻¹b, c) and its cost-aware line search. No multiplier.

Source tags: [O] OmniSafe PCPO (configs/on-policy/PCPO.yaml, second_order/pcpo.py), [P] the PCPO
paper's eq. 7, [D] ours. The paper ran OmniSafe's PCPO with its defaults (App. D): they are the
defaults, OmniSafe's step included (``projection="omnisafe"``); the paper's equation is
``projection="kl"``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.algorithms.cpo import config as cpo
from lac_rllib.algorithms.cpo.config import CPO_CASE, CostStepParams, CPOConfig
from lac_rllib.constrained import fields
from lac_rllib.constrained.fields import INT_GE_1, one_of, or_none, param
from lac_rllib.constrained.search_space import lr
from lac_rllib.families.trust_region.config import OMNISAFE_STEP

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe")
PROJECTIONS = ("omnisafe", "kl", "l2")


@dataclasses.dataclass
class PCPOParams(CostStepParams):
    """The PCPO hyperparameters: its preset, the projection and the line search's length, after the
    cost-gap and trust-region fields (no multiplier)."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D] (see ``PRESETS``)."""

    # --- PCPO ---
    projection: str = param("omnisafe", accepts=one_of(PROJECTIONS))
    """The step: "kl", eq. 7's, η·H⁻¹g − max(0, (η·gᵀH⁻¹b + c)/bᵀH⁻¹b)·H⁻¹b with η = √(2δ/gᵀH⁻¹g),
    the reward's TRPO step projected in the KL metric [P]; "l2", projected in the Euclidean one
    (L = I) [P]; "omnisafe", [O pcpo.py:80, 102-109], whose reward step is η·H(H⁻¹g) ≈ η·g (the plain
    gradient) with the KL projection's coefficient, η and H in [O]'s units (its KL averaged over
    the action's dimensions: on the summed KL, kl_convention="sum", the reward step is divided by
    act_dim, as [O]'s δ and q would make it); with the ``omnisafe`` preset it is [O]'s step exactly
    (tests/algorithms/pcpo/test_pcpo_golden.py). Before that division (and with η·g for η·Hx) the
    reward step was act_dim times [O]'s on the default KL. With several constraints (``constraints``)
    "omnisafe", a one-constraint step, projects as "kl" does."""
    backtrack_iters: int = param(200, accepts=INT_GE_1)
    """Fractions 1, c, c², … of the step the line search tries before it keeps θ_old [O
    _update_actor: total_steps=200]."""


PRESETS: dict[str, dict[str, Any]] = {name: dict(values) for name, values in cpo.PRESETS.items() if name != "ssa"}
# [O]'s KL and CG; PCPO has no dual to set (tests/algorithms/pcpo/test_pcpo_golden.py).
PRESETS["omnisafe"] = dict(OMNISAFE_STEP)


class PCPOConfig(CPOConfig):
    """Config for :class:`lac_rllib.algorithms.pcpo.algorithm.PCPO`; fields: :class:`PCPOParams`."""

    ALGO = "pcpo"
    OMNISAFE_NAME = "PCPO"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = PCPOParams, fields.FieldSet(PCPOParams, "PCPO"), PRESETS
    SEARCH_SPACE = {
        **CPOConfig.SEARCH_SPACE,
        "critic_lr": lr("[O] the critics' lr (PCPO's cost critic sets its projection)"),
    }
    REPORTED_KEYS = tuple(k for k in CPOConfig.REPORTED_KEYS if k != CPO_CASE)  # no cases
    ALGORITHM_CLASS = "lac_rllib.algorithms.pcpo.algorithm.PCPO"
    LEARNER_CLASS = "lac_rllib.algorithms.pcpo.learner.PCPOTorchLearner"
