"""FOCOPSConfig: First-Order Constrained Optimization in Policy Space = PPO-Lag with FOCOPS's policy loss.

FOCOPS fits the policy to the optimal update policy of the constrained problem in the
non-parametric space, π*(a|s) ∝ π_old(a|s)·exp(A(s, a)/λ_F) (Zhang et al. 2020, eq. 8; the
distribution LAC's Langevin chain samples from, the paper's §2 and App. A), by the loss of its
eq. (11) (learner.py). Everything else is PPO-Lag's: the module (π, V_R, V_C, ν), the cost GAE,
the multiplier's step, the KL early stop, the minibatch epochs, the training step.

Source tags: [O] OmniSafe FOCOPS (configs/on-policy/FOCOPS.yaml, algorithms/.../focops.py), [F]
the paper's source, ymzhang01/focops (focops_main.py, data_generator.py; the paper's App. D), [D]
ours. The defaults are [O]'s; the ``paper`` preset is [F]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.algorithms.ppo_lag import config as ppo_lag
from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.fields import BOOL, POSITIVE, one_of, or_none, param
from lac_rllib.constrained.search_space import Searched
from lac_rllib.families.on_policy.config import OMNISAFE_BUDGET, OnPolicyLagParams

#: The learner's own result keys, beside the on-policy family's (lac_rllib/constrained/metrics.py).
TRUST_REGION_FRACTION = "trust_region_fraction"  # FOCOPS: fraction of rows with KL(π ‖ π_old) ≤ η, last minibatch

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "omnisafe", "paper")


@dataclasses.dataclass
class FOCOPSParams(OnPolicyLagParams):
    """The FOCOPS hyperparameters: its preset, the loss's λ_F and η and the multiplier's bound,
    after the on-policy Lagrangian family's fields (PPO-Lag's but its clip)."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco", "safety_gym" and "omnisafe" [O], "tiny" [D], "paper" [F]
    (see ``PRESETS``)."""

    # --- FOCOPS ---
    focops_lam: float = param(1.5, accepts=POSITIVE)
    """λ_F, the temperature of the optimal update policy π* ∝ π_old·exp(A/λ_F): the loss weighs the
    advantage by 1/λ_F against the KL to π_old [O focops_lam 1.5; F lam 1.5]."""
    focops_eta: float = param(0.02, accepts=POSITIVE)
    """η of the per-state indicator 1[KL(π_θ ‖ π_old)[s] ≤ η]: a state whose policy has moved
    further than η drops out of the loss [O focops_eta 0.02; F eta 0.02]."""
    focops_indicator: str = param("broadcast", accepts=one_of(("broadcast", "per_row")))
    """How the indicator 1[KL ≤ η] meets the surrogate. "broadcast": OmniSafe 0.5.0's loss [O
    focops.py:103-107, ``(kl − r·A/λ_F)·1[kl ≤ η]`` with kl (B, 1) and r·A (B,), a B × B matrix,
    averaged]: mean_i(1_i·kl_i) − f·mean_j(r_j·A_j)/λ_F with f the fraction of rows inside η, so
    every row keeps its surrogate gradient, scaled by f; OmniSafe's step exactly
    (tests/algorithms/focops/test_focops_golden.py). "per_row": the paper's eq. (11) per state [F
    focops_main.py, its tensors all (B, 1)]: a row beyond η loses its surrogate gradient (the
    ``paper`` preset). The default by the curves at equal seeds on SafetyPointGoal1 (500k, seeds
    0-1): 19.70 ± 2.14 / 49.4 against 12.83 ± 3.70 / 57.9, OmniSafe's curve 21.8 / 49
    (docs/fidelity/pointgoal1-focops-indicator/)."""
    nu_divides_advantage: bool = param(True, accepts=BOOL)
    """A = (A^R − ν·A^C)/(1 + ν) (True) [O FOCOPS._compute_adv_surrogate], or A^R − ν·A^C (False) [F
    focops_main.py], whose scale grows with ν."""
    nu_max: float | None = param(2.0, accepts=or_none(POSITIVE))
    """ν is held in [0, nu_max] after each step [O lagrangian_upper_bound 2.0; F nu_max 2.0]; None =
    no upper bound."""


# [F] focops_main.py's defaults as the paper ran them (App. D: FOCOPS from ymzhang01/focops): its
# per-row loss (eq. 11), 2048-step batches, 10 epochs of 64 rows, ν ← clip(ν + 0.01·(J̄_C − b), 0, 2) from 0 on this
# batch's episodes, no 1/(1 + ν), both advantages standardised, lr 3e-4 for the three networks,
# the policy's decaying linearly over the run, critic L2 1e-3, a KL stop of 0.02 after each
# epoch, clip 40, log σ₀ −0.5, (64, 64) tanh, running obs normalisation clipped at 5.
# Approximations: [F]'s critics' lr decays too (here constant), its clip is on the policy only
# (here on each network), its epoch KL is KL(π ‖ π_old) (here KL(π_old ‖ π), PPO-Lag's), and its
# J̄_C is the discounted episode cost (here the task's convention: discounted on the focops/
# tasks, summed on Safety-Gymnasium, as the limit 25 counts it).
PAPER = {"focops_indicator": "per_row",
         "nu_init": 0.0, "nu_optimizer": "sgd", "lagrangian_lr": 0.01, "nu_max": 2.0, "cost_window": None,
         "nu_divides_advantage": False, "standardize_cost_advantages": True, "critic_lr": 3e-4, "critic_l2": 1e-3,
         "lr": 3e-4, "policy_lr_schedule": "linear", "lr_decay_horizon": None, "target_kl": 0.02,
         "kl_stop_late": False, "kl_stop_critics": True, "grad_clip": 40.0, "hidden": (64, 64), "activation": "tanh",
         "log_std_init": -0.5, "gamma": 0.99, "cost_gamma": 0.99, "lambda_": 0.95,
         "train_batch_size_per_learner": 2048, "num_epochs": 10, "minibatch_size": 64, "num_envs_per_env_runner": 1}
PRESETS: dict[str, dict[str, Any]] = {
    **{name: dict(values) for name, values in ppo_lag.PRESETS.items() if name != "ssa"},  # [O] as PPO-Lag's
    "omnisafe": {"lr_decay_horizon": OMNISAFE_BUDGET, "focops_indicator": "broadcast"},  # [O] named
    "paper": PAPER,
}


class FOCOPSConfig(PPOLagConfig):
    """Config for :class:`lac_rllib.algorithms.focops.algorithm.FOCOPS`; fields: :class:`FOCOPSParams`."""

    ALGO = "focops"
    OMNISAFE_NAME = "FOCOPS"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = FOCOPSParams, fields.FieldSet(FOCOPSParams, "FOCOPS"), PRESETS
    SEARCH_SPACE = {
        "lr": PPOLagConfig.SEARCH_SPACE["lr"],
        "lagrangian_lr": PPOLagConfig.SEARCH_SPACE["lagrangian_lr"],
        "focops_lam": Searched("uniform", "[F] Zhang et al. 2020 study FOCOPS's sensitivity to λ", (0.5, 3.0)),
        "focops_eta": Searched("loguniform", "[F] the trust-region indicator's radius δ (its KL bound)",
                               around=3.0),
    }
    REPORTED_KEYS = (*metrics.PPO_LAG_KEYS, TRUST_REGION_FRACTION)
    ALGORITHM_CLASS = "lac_rllib.algorithms.focops.algorithm.FOCOPS"
    LEARNER_CLASS = "lac_rllib.algorithms.focops.learner.FOCOPSTorchLearner"
