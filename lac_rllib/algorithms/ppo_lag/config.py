"""PPOLagConfig: PPO-Lagrangian = the on-policy base (families/on_policy/config.py) + the Lagrange
multiplier + PPO's clip. Source tags: [O] OmniSafe PPOLag (configs/on-policy/PPOLag.yaml), [S]
safety-starter-agents PPO-L (pg/run_agent.py, the paper's PPO-L, App. D), [D] ours. The defaults
are [O]'s; the ``ssa`` preset is [S]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from lac_rllib.constrained import fields
from lac_rllib.constrained.fields import POSITIVE, one_of, or_none, param
from lac_rllib.constrained.search_space import MULTIPLIER_LR, Searched, lr
from lac_rllib.families.on_policy.config import ON_POLICY_PRESETS, OnPolicyConfig, OnPolicyLagParams

PRESET_NAMES = ("mujoco", "safety_gym", "tiny", "ssa")


@dataclasses.dataclass
class PPOLagParams(OnPolicyLagParams):
    """The PPO-Lag hyperparameters: its preset and clip, after the family's fields."""

    # --- preset ---
    preset: str | None = param(None, accepts=or_none(one_of(PRESET_NAMES)))
    """The preset applied: the task's (``.task(id)``) or one named with ``.task(id, preset=...)`` /
    ``training(preset=...)``, which applies its values first: "mujoco", "safety_gym" [O], "tiny" [D],
    "ssa" [S] (see ``PRESETS``)."""

    # --- policy ---
    clip_param: float = param(0.2, accepts=POSITIVE)
    """ε of PPO's clipped surrogate (RLlib's field; its default is 0.3) [O, S]."""


PRESETS: dict[str, dict[str, Any]] = {
    **ON_POLICY_PRESETS,
    # [D] the family's tiny sizes and a faster ν (lr 0.1) for a run of 20 iterations.
    "tiny": {**ON_POLICY_PRESETS["tiny"], "lagrangian_lr": 0.1},
    # [S] safety-starter-agents PPO-L as the paper ran it (scripts/experiment.py: 30k steps per
    # epoch, (256, 256)); Adam on softplus⁻¹(ν) from ν₀ = 1 at lr 0.05 on this epoch's mean cost;
    # 80 full-batch policy steps with its KL stop, 80 value steps at 1e-3; no obs normalisation,
    # no gradient clip, no critic L2, no lr decay. Approximations: its value targets are discounted
    # returns (here GAE-λ returns), its cost surrogate is unclipped (here clipped with the reward's),
    # and it treats a time-limit end as terminal (here bootstrapped).
    "ssa": {"nu_init": 1.0, "lagrangian_lr": 0.05, "nu_parametrization": "softplus", "cost_window": None,
            "lambda_": 0.97, "critic_lr": 1e-3, "critic_l2": 0.0, "lr": 3e-4, "policy_lr_schedule": "constant",
            "target_kl": 0.012, "kl_stop_late": True, "kl_stop_critics": False, "grad_clip": None,
            "hidden": (256, 256), "log_std_init": -0.5, "obs_normalization": False,
            "train_batch_size_per_learner": 30_000, "num_epochs": 80, "minibatch_size": None,
            "num_envs_per_env_runner": 10},
}


class PPOLagConfig(OnPolicyConfig):
    """Config for :class:`lac_rllib.algorithms.ppo_lag.algorithm.PPOLag`; fields: :class:`PPOLagParams`.

    ``PPOLagConfig().task(id)`` applies the task's preset; ``.task(id, preset="ssa")`` (or
    ``training(preset="ssa")``, which applies its values first: the other values of the same call
    win) the paper's PPO-L. Explicit ``training(...)`` values win over presets.
    """

    # A cost critic, cost advantage and multiplier per constraint (families/on_policy/lagrangian.py);
    # FOCOPS and CUP inherit it.
    SEVERAL_CONSTRAINTS = True

    ALGO = "ppo_lag"
    OMNISAFE_NAME = "PPOLag"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = PPOLagParams, fields.FieldSet(PPOLagParams, "PPO-Lag"), PRESETS
    SEARCH_SPACE = {
        "lr": OnPolicyConfig.SEARCH_SPACE["lr"],
        "lagrangian_lr": lr(MULTIPLIER_LR),
        "clip_param": OnPolicyConfig.SEARCH_SPACE["clip_param"],
        "target_kl": Searched("loguniform", "[O] 0.01 or 0.02 across its presets: a factor 3 either side",
                              around=3.0),
    }
    ALGORITHM_CLASS = "lac_rllib.algorithms.ppo_lag.algorithm.PPOLag"
    LEARNER_CLASS = "lac_rllib.algorithms.ppo_lag.learner.PPOLagTorchLearner"
