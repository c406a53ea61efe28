"""TrustRegionConfig: the trust-region family's config (TRPO-Lag, CPO, PCPO) on the on-policy base.

The policy takes one trust-region step per iteration on the whole batch (Schulman et al. 2015:
the natural gradient by conjugate gradient, scaled onto KL = δ, then a backtracking line search;
learner.py) instead of Adam's minibatch epochs; the critics keep theirs. Everything
else is the on-policy base's: the module (π, V_R, V_C, ν), the cost GAE, Ĵ_C, the training step.
:class:`TrustRegionParams` are the fields the family shares.

Source tags: [O] OmniSafe (configs/on-policy/TRPOLag.yaml, CPO.yaml, PCPO.yaml, base/natural_pg.py,
base/trpo.py), [S] safety-starter-agents (pg/agents.py ``TRPOAgent``, pg/run_agent.py,
scripts/experiment.py: the paper's TRPO-L and CPO, App. D), [D] ours. The defaults are [O]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.constrained import metrics
from lac_rllib.constrained.fields import BOOL, FRACTION, INT_GE_1, NON_NEGATIVE, POSITIVE, one_of, or_none, param
from lac_rllib.constrained.search_space import Searched, lr
from lac_rllib.families.on_policy.config import OnPolicyConfig, OnPolicyParams

#: The family's own result keys: one step of the policy per iteration, whose KL(π_old ‖ π) over
#: the batch afterwards is KL_FULL_BATCH.
LINE_SEARCH_FRACTION = "line_search_fraction"  # the fraction of the full step kept; 0: none accepted, θ_old kept
LINE_SEARCH_BACKTRACKS = "line_search_backtracks"  # fractions rejected before the accepted one (all if none)

KL_CONVENTIONS = ("sum", "mean")


@dataclasses.dataclass
class TrustRegionParams(OnPolicyParams):
    """The trust-region family's fields (TRPO-Lag, CPO, PCPO), after the on-policy family's: the
    step's radius, conjugate gradient and line search, and the critics' epochs, with [O]'s defaults
    (TRPOLag.yaml, CPO.yaml and PCPO.yaml agree on them). The policy takes no Adam step: the family's
    lr, policy_lr_schedule, lr_decay_horizon, kl_stop_late and kl_stop_critics change nothing here."""

    # --- trust region ---
    target_kl: float = param(0.01, accepts=POSITIVE)
    """δ, the trust region: the step is scaled onto ½ΔθᵀHΔθ = δ and the line search accepts a point
    only if the mean KL(π_old ‖ π) over the batch is at most δ [O target_kl 0.01; S target_kl 0.01].
    Per action dimension with kl_per_action_dim. There is no KL early stop."""
    kl_per_action_dim: bool = param(True, accepts=BOOL)
    """target_kl is per action dimension (True) [O: its Normal's KL is averaged over the action's
    dimensions], so the bound on RLlib's KL, summed over them, is target_kl·act_dim (0.02 on the
    Point and Car tasks, 0.17 on Humanoid); False: target_kl bounds the summed KL itself [S
    gaussian_kl sums over the dimensions]. The step measures the KL kl_convention names (max_kl)."""
    kl_convention: str = param("sum", accepts=one_of(KL_CONVENTIONS))
    """The KL the step measures: the one whose Hessian the Fisher-vector product takes (so what
    cg_damping weighs against), in q = xᵀHx, in the line search's KL ≤ δ and as kl_full_batch
    reports it. "sum": RLlib's, summed over the action's dimensions [S gaussian_kl]; "mean":
    averaged over them, OmniSafe's [O 0.5.0 natural_pg.py:95, trpo.py:113, cpo.py:133:
    ``kl_divergence(p, q).mean()`` of a (B, act_dim) ``Normal``]. Its Hessian is act_dim times
    smaller, so the same cg_damping weighs act_dim times more: [O]'s (H/d + 0.1·I) [O
    natural_pg.py:119] is (H + 0.1·d·I)/d, i.e. the steps of damping 0.1·act_dim on the summed KL
    (0.2 on the Point and Car tasks; x and q are then in other units, the steps the same, CG's ε
    aside). With "mean", x = H⁻¹g, q and the TRPO, CPO and PCPO steps are [O]'s to rounding. δ is
    per action dimension or not as kl_per_action_dim says, under either. The default keeps the
    runs recorded with it; the ``omnisafe`` preset takes "mean"
    (tests/algorithms/trpo_lag/test_trpo_lag_golden.py)."""
    cg_iters: int = param(15, accepts=INT_GE_1)
    """Conjugate-gradient iterations of each solve H·x = g [O cg_iters 15; S cg_iters 10]."""
    cg_damping: float = param(0.1, accepts=NON_NEGATIVE)
    """Damping of the Fisher-vector product, (H + cg_damping·I)·v, H the Hessian of the KL that
    kl_convention names [O cg_damping 0.1 on its mean KL; S damping_coeff 0.1 on the summed KL]."""
    cg_eps: float = param(0.0, accepts=NON_NEGATIVE)
    """ε added to both denominators of conjugate gradient's recurrence, α = rᵀr/(pᵀHp + ε) and
    β = r'ᵀr'/(rᵀr + ε) [O math.py:123, 129: 1e-6; S: 1e-8 in α only]. It biases the solve once rᵀr
    nears it (on [O]'s KL, 1.4e-4 relative on xHx in the TRPO-Lag golden step), so the default is
    Schulman's 0; the ``omnisafe`` preset takes [O]'s 1e-6."""
    backtrack_iters: int = param(15, accepts=INT_GE_1)
    """Fractions 1, c, c², … (c = backtrack_coeff) of the step the line search tries before it keeps
    θ_old [O trpo.py _search_step_size: 15; S backtrack_iters 10]."""
    backtrack_coeff: float = param(0.8, accepts=FRACTION)
    """c, the line search's decay between tries [O decay 0.8; S backtrack_coeff 0.8]."""

    # --- critics ---
    critic_lr: float = param(1e-3, accepts=POSITIVE)
    """Adam learning rate of the reward and the cost critic, constant [O critic lr 0.001; S vf_lr 1e-3]."""
    num_epochs: int = param(10, accepts=INT_GE_1)
    """The critics' passes over the iteration's batch after the policy's step (RLlib's field) [O
    update_iters 10; S: vf_iters 80 steps on the whole batch]."""
    minibatch_size: int | None = param(128, accepts=or_none(INT_GE_1))
    """Rows per critic step (RLlib's field; phantom rows included, masked) [O batch_size 128]; None =
    the whole batch per step [S]."""


#: [S] the paper's TRPO-L and CPO (scripts/experiment.py, run_agent.py, agents.py): 30k steps per
#: epoch, (256, 256) tanh, log σ₀ −0.5, λ_GAE 0.97, δ 0.01 on the summed KL, 10 CG iterations,
#: damping 0.1, 10 backtracks × 0.8, 80 full-batch critic steps at 1e-3, no obs normalisation, no
#: gradient clip, no critic L2; Ĵ_C over this epoch's episodes. Approximations: its value targets
#: are discounted returns (here GAE-λ returns), its two critics share one Adam (here one each), and
#: it treats a time-limit end as terminal (here bootstrapped).
SSA_TRUST_REGION: dict[str, Any] = {
    "target_kl": 0.01, "kl_per_action_dim": False, "cg_iters": 10, "cg_damping": 0.1, "backtrack_iters": 10,
    "backtrack_coeff": 0.8, "cost_window": None, "lambda_": 0.97, "critic_lr": 1e-3, "critic_l2": 0.0,
    "grad_clip": None, "hidden": (256, 256), "log_std_init": -0.5, "obs_normalization": False,
    "train_batch_size_per_learner": 30_000, "num_epochs": 80, "minibatch_size": None, "num_envs_per_env_runner": 10,
}
#: [D] lac/PointHazard-v0 (100-step episodes, limit 2): PPO-Lag's tiny sizes (2000 steps per
#: iteration over 10 envs, the critics' 10 epochs of 8 minibatches at 1e-3, Ĵ_C over the last 20
#: episodes) with δ 0.02 per action dimension: one step per iteration, and at [O]'s 0.01 TRPO-Lag
#: reaches the goal later (seed 0: return 0.83 at 40k steps, the quick budget, against 0.96; both
#: ~0.99 at cost ~2.1 by 100k).
TINY_TRUST_REGION: dict[str, Any] = {
    "train_batch_size_per_learner": 2000, "num_envs_per_env_runner": 10, "minibatch_size": 250, "num_epochs": 10,
    "critic_lr": 1e-3, "cost_window": 20, "target_kl": 0.02,
}
#: [O]'s own step: its KL averaged over the action's dimensions (so its damping) and its CG's ε.
OMNISAFE_STEP: dict[str, Any] = {"kl_convention": "mean", "cg_eps": 1e-6}
#: The family's sizes per task preset: [O]'s yaml files are the defaults; 10 and 5 envs split the
#: 20k steps into whole 1000-step episodes per env (speed only).
TRUST_REGION_PRESETS: dict[str, dict[str, Any]] = {
    "safety_gym": {"num_envs_per_env_runner": 10},
    "mujoco": {"num_envs_per_env_runner": 5},
    "tiny": dict(TINY_TRUST_REGION),
    "omnisafe": dict(OMNISAFE_STEP),
}

#: What each iteration's row reports beside the top-level keys: PPO-Lag's but its epoch count (the
#: KL after the step is kl_full_batch), and the line search's outcome.
TRUST_REGION_KEYS = (metrics.POLICY_LOSS, metrics.VF_LOSS, metrics.COST_VF_LOSS, metrics.COST_WINDOW_MEAN,
                     metrics.KL_FULL_BATCH, LINE_SEARCH_FRACTION, LINE_SEARCH_BACKTRACKS)


class TrustRegionConfig(OnPolicyConfig):
    """The trust-region family's config: TRPO-Lag's, CPO's and PCPO's extend it."""

    REPORTED_KEYS = TRUST_REGION_KEYS
    #: The family's searched fields (not the on-policy base's: the policy takes no lr nor clip).
    SEARCH_SPACE = {
        "target_kl": Searched("loguniform", "[O] the trust region δ, 0.01 or 0.02 across presets", around=3.0),
        "cg_damping": lr("docs/baselines.md: the references' damping conventions differ act_dim× (trust-region KL)"),
        "critic_lr": lr("[O] the critics' lr, 1e-3 everywhere: a decade either side"),
    }

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict:
        """update_step.py: an iteration of 10·``steps`` env steps (PPO-Lag's size; there is no KL
        early stop to switch off)."""
        return {"train_batch_size_per_learner": 10 * steps} if benchmark == "update_step" else {}

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """Update seconds per env step on one CPU beyond sampling: half the on-policy base's.
        Measured at the tiny sizes, same machine and session: 100k steps in 26 s (TRPO-Lag), 33-35 s
        (PCPO, CPO), 41 s (PPO-Lag): the critics' steps are two of PPO-Lag's three networks' and the
        policy's one step (~20-35 products on 2000 rows) costs less than its 80 minibatch steps."""
        return 0.5 * OnPolicyConfig.plan_update_s(params, preset)

    def max_kl(self, action_dim: int) -> float:
        """δ on the KL the step measures (kl_convention). On RLlib's, summed over the action's
        dimensions: target_kl·action_dim with kl_per_action_dim [O], else target_kl [S]; on their
        mean: target_kl [O], else target_kl/action_dim."""
        if self.kl_convention == "mean":
            return float(self.target_kl) / (1 if self.kl_per_action_dim else action_dim)
        return float(self.target_kl) * (action_dim if self.kl_per_action_dim else 1)
