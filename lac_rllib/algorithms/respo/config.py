"""RESPOConfig: Reachability Estimation for Safe Policy Optimization = PPO-Lag + a reach critic.

RESPO (Ganai et al. 2023) is PPO-L with a third critic, V_p(s) ∈ (0, 1), the discounted
probability that the policy reaches a state of positive cost from s (module.py, reachability.py).
The policy's loss weighs the reward surrogate by ψ = 1 − V_p (the states from which a violation is
unlikely) and the cost surrogate by ν·ψ + V_p, and ν steps on the violation seen from those states
only, (J_C − b)·mean(1 − V_p) (learner.py). Everything else is PPO-Lag's: the cost GAE, the KL
stop, the training step.

Source tags: [G] Ganai et al.'s code (milanganai.github.io, NeurIPS2023/code/respo.py and
core_respo.py), [D] ours. RESPO is not in OmniSafe: the defaults are [G]'s (a spinning-up PPO-L,
the same recipe as PPO-Lag's ``ssa`` preset), except b of ν's step (``multiplier_cost_limit``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.fields import (
    BOOL,
    FINITE,
    FRACTION,
    INT_GE_1,
    LAYERS,
    NON_NEGATIVE,
    POSITIVE,
    one_of,
    or_none,
    param,
)
from lac_rllib.constrained.search_space import lr
from lac_rllib.families.on_policy.config import ACTIVATIONS, NU_PARAMETRIZATIONS, OnPolicyLagParams

#: The learner's own result keys, beside the on-policy family's (lac_rllib/constrained/metrics.py).
REACH_VF_LOSS = "reach_vf_loss"  # RESPO: masked mean (V_p − p-target)², last minibatch
REACH_PROB_MEAN = "reach_prob_mean"  # RESPO: mean V_p(s) over the batch at collection

PRESET_NAMES = ("mujoco", "safety_gym", "tiny")
P_INIT = 0.25  # [G] penalty_param = 0.25, ν = softplus(p)
NU_INIT = math.log1p(math.exp(P_INIT))  # ν₀ = softplus(0.25) ≈ 0.826
RESPO_BUDGET = 9_000_000  # env steps of [G]'s runs (respo.py __main__: num_steps 9e6, 300 epochs of 30k)


@dataclasses.dataclass
class RESPOParams(OnPolicyLagParams):
    """The RESPO hyperparameters: its preset, PPO's clip, the reach critic's and ν's b, after the
    on-policy Lagrangian family's fields with [G]'s defaults."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``: "mujoco" and "safety_gym" [G], "tiny" [D] (see ``PRESETS``)."""

    # --- reachability ---
    reach_gamma: float = param(0.99, accepts=FRACTION)
    """γ_p of the reachability target p_t = max(1[c_t > 0], γ_p·p_{t+1}) [G finish_path: mu 0.99]."""
    reach_critic_lr: float = param(1e-4, accepts=POSITIVE)
    """Adam learning rate of the reach critic V_p at the start [G pvf_lr 1e-4]; it decays with the
    others (decay_every_lr). No L2 on it [G]."""
    reach_weighted: bool = param(True, accepts=BOOL)
    """The policy's loss weighs its surrogates by V_p at collection (ψ = 1 − V_p: reward term ·ψ,
    cost term ·(ν·ψ + 1 − ψ)) [G]; False: ψ ≡ 1, PPO-Lag's loss on A^R − ν·A^C over 1 + ν. With ν
    pinned at 0 too, the constraint is off (V_p's weight keeps the cost term alive at ν = 0)."""
    decay_every_lr: bool = param(True, accepts=BOOL)
    """The three critics' and ν's learning rates decay linearly to 0 with the policy's
    (policy_lr_schedule, over lr_decay_horizon) [G: a LinearLR on each of its five optimizers];
    False: they stay constant, as PPO-Lag's."""

    # --- Lagrange multiplier, [G]'s ---
    multiplier_cost_limit: float | None = param(None, accepts=or_none(NON_NEGATIVE))
    """b of ν's step, whose loss is −p·(J_C − b)·mean(1 − V_p): None = the run's cost limit (the
    task's, or cost_limit) [D], as every other algorithm here; 0.0 = [G]'s (compute_loss_pi sets
    cost_limit = 0: ν grows while any cost is seen). The task's limit still judges feasibility."""
    nu_init: float = param(NU_INIT, accepts=NON_NEGATIVE)
    """ν₀ = softplus(0.25) ≈ 0.826 [G penalty_param 0.25, ν = softplus(p)]."""
    lagrangian_lr: float = param(5e-5, accepts=NON_NEGATIVE)
    """Adam's learning rate on p (ν = softplus(p)) at the start, one step per iteration before the
    policy's [G penalty_lr 5e-5]; it decays with the policy's (decay_every_lr)."""
    nu_parametrization: str = param("softplus", accepts=one_of(NU_PARAMETRIZATIONS))
    """"softplus": ν = softplus(p), Adam on p [G]; "direct": Adam on ν, then ν ← max(ν, 0)."""
    cost_window: int | None = param(None, accepts=or_none(INT_GE_1))
    """J_C of ν's step: the mean cost of the episodes completed this iteration (None) [G EpCost of
    the epoch], or of the last cost_window completed episodes."""

    # --- advantages and critics, [G]'s ---
    lambda_: float = param(0.97, accepts=FRACTION)
    """λ of both GAEs (RLlib's field) [G lam 0.97]."""
    critic_lr: float = param(1e-3, accepts=POSITIVE)
    """Adam learning rate of the reward and the cost critic at the start [G vf_lr 1e-3]."""
    critic_l2: float = param(0.0, accepts=NON_NEGATIVE)
    """Weight of Σθ² over the reward and cost critics' parameters [G: none]."""

    # --- policy, [G]'s ---
    clip_param: float = param(0.2, accepts=POSITIVE)
    """ε of the clipped reward surrogate (RLlib's field) [G clip_ratio 0.2]; the cost surrogate is unclipped [G]."""
    target_kl: float | None = param(0.012, accepts=or_none(POSITIVE))
    """KL stop: before each epoch, the policy stops for the iteration once the full-batch KL(π_old ‖ π)
    exceeds it [G: 1.2·target_kl 0.01, checked before each of its 80 steps]; None = off."""
    kl_stop_critics: bool = param(False, accepts=BOOL)
    """The KL stop also ends the critics' steps (True); False: they run all num_epochs [G: the three
    critics always take their 80 steps]."""
    grad_clip: float | None = param(None, accepts=or_none(POSITIVE))
    """Global-norm gradient clip of each network (RLlib's field) [G: none]; None = off."""
    hidden: tuple = param((256, 256), accepts=LAYERS)
    """Hidden layers of each of the four MLPs (policy, reward, cost and reach critics) [G --hid 256 --l 2]."""
    activation: str = param("tanh", accepts=one_of(ACTIVATIONS))
    """Activation of the MLPs [G nn.Tanh]."""
    log_std_init: float = param(-0.5, accepts=FINITE)
    """Initial state-independent log σ of the Gaussian policy [G MLPGaussianActor: −0.5]."""
    obs_normalization: bool = param(False, accepts=BOOL)
    """Running mean/std observation filter [G: none]."""

    # --- data and schedule, [G]'s ---
    train_batch_size_per_learner: int = param(30_000, accepts=INT_GE_1)
    """Env steps sampled per iteration (RLlib's field) [G steps_per_epoch 30k]."""
    num_epochs: int = param(80, accepts=INT_GE_1)
    """Passes over the iteration's batch (RLlib's field) [G train_pi_iters, train_v_iters 80]."""
    minibatch_size: int | None = param(None, accepts=or_none(INT_GE_1))
    """Rows per gradient step (RLlib's field; phantom rows included, masked); None = the whole batch
    per step [G]."""


PRESETS: dict[str, dict[str, Any]] = {
    # [G]'s values are the defaults, every lr decaying over its 9e6-step runs (a shorter run trains
    # at the rates [G]'s had at that step); 10 and 5 envs split the 30k steps into whole 1000-step
    # episodes per env (speed only).
    "safety_gym": {"num_envs_per_env_runner": 10, "lr_decay_horizon": RESPO_BUDGET},
    "mujoco": {"num_envs_per_env_runner": 5, "lr_decay_horizon": RESPO_BUDGET},
    # [D] PPO-Lag's tiny sizes and rates (lac/PointHazard-v0 in ~40k steps: 20 iterations of 2000
    # steps, 10 epochs of 8 minibatches at lr 1e-3, a fast ν), its (64, 64) networks and KL stop,
    # the reach critic at the critics' rate.
    "tiny": {"train_batch_size_per_learner": 2000, "num_envs_per_env_runner": 10, "minibatch_size": 250,
             "num_epochs": 10, "lr": 1e-3, "critic_lr": 1e-3, "reach_critic_lr": 1e-3, "lagrangian_lr": 0.1,
             "hidden": (64, 64), "target_kl": 0.02},
}


class RESPOConfig(PPOLagConfig):
    """Config for :class:`lac_rllib.algorithms.respo.algorithm.RESPO`; fields: :class:`RESPOParams`."""

    SEVERAL_CONSTRAINTS = True  # a reach critic, ψ_k and reach-weighted ν_k per constraint (learner.py)

    ALGO = "respo"
    PARAMS, FIELDS, PRESETS = RESPOParams, fields.FieldSet(RESPOParams, "RESPO"), PRESETS
    SEARCH_SPACE = {
        "lr": PPOLagConfig.SEARCH_SPACE["lr"],
        "lagrangian_lr": PPOLagConfig.SEARCH_SPACE["lagrangian_lr"],
        "reach_critic_lr": lr("RESPO's authors' code: its reachability critic learns on a timescale of its own"),
    }
    REPORTED_KEYS = (*metrics.PPO_LAG_KEYS, REACH_VF_LOSS, REACH_PROB_MEAN)
    ALGORITHM_CLASS = "lac_rllib.algorithms.respo.algorithm.RESPO"
    RL_MODULE_CLASS = "lac_rllib.algorithms.respo.module.RESPOTorchRLModule"
    LEARNER_CLASS = "lac_rllib.algorithms.respo.learner.RESPOTorchLearner"

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict:
        """update_step.py at PPO-Lag's shapes (64-row minibatches of (64, 64) networks, 40 epochs, its
        KL stop off), so its gradient step is timed against its house's on the same work;
        iteration.py at its preset."""
        if benchmark != "update_step":
            return {}
        return {**PPOLagConfig.benchmark_fields(benchmark, steps), "minibatch_size": 64, "num_epochs": 40,
                "hidden": (64, 64)}

    def lr_or_schedule(self, lr: float):
        """A critic's (or ν's) lr as RLlib's ``lr_or_lr_schedule``: decaying as the policy's when
        ``decay_every_lr`` [G], else constant."""
        if not self.decay_every_lr or self.policy_lr_schedule == "constant":
            return lr
        return [[0, lr], [self.lr_horizon, 0.0]]

    @property
    def multiplier_limit(self) -> float:
        """b of ν's step: ``multiplier_cost_limit``, else the run's cost limit."""
        if self.multiplier_cost_limit is not None:
            return float(self.multiplier_cost_limit)
        return self.effective_cost_limit
