"""OnPolicyConfig: the on-policy family's config on RLlib's PPO (PPO-Lag, P3O, FOCOPS, CUP, RESPO and
the trust-region family), its fields declared once with their defaults and sources.

Fields live in :class:`OnPolicyParams` (and the multiplier's in :class:`OnPolicyLagParams`), one
docstring each; a config copies its ``PARAMS`` onto itself. Where a field is an RLlib setting it
keeps RLlib's name (``lr``, ``gamma``, ``lambda_``, ``num_epochs``, ``minibatch_size``,
``train_batch_size_per_learner``, ``vf_clip_param``, ``grad_clip``, ``num_envs_per_env_runner``):
the field *is* that RLlib attribute, declared with the family's default, so RLlib reads it as it
is and a sweep's ``--set`` reaches it. RLlib settings the family pins (no KL penalty, separate
networks, a free log σ, no entropy bonus) are set in ``__init__`` and are not fields; the networks'
shapes are fields of ours (``hidden``, ``activation``, ``log_std_init``) that reach RLlib's
``model_config``.

Source tags: [O] OmniSafe PPO / PPOLag (configs/on-policy/PPOLag.yaml and the code it runs), [S]
safety-starter-agents PPO-L (pg/run_agent.py, the paper's PPO-L, App. D), [F] ymzhang01/focops,
[R] RLlib's PPO, [D] ours. The defaults are [O]'s.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.algorithms.ppo.ppo import PPOConfig
from ray.rllib.connectors.learner import AddColumnsFromEpisodesToTrainBatch
from ray.rllib.utils.annotations import override

from lac_rllib.constrained import metrics
from lac_rllib.constrained.costs import AddCostsFromInfos
from lac_rllib.constrained.fields import (
    BOOL,
    FINITE,
    FRACTION,
    INT_GE_1,
    LAYERS,
    NON_NEGATIVE,
    POSITIVE,
    Accepted,
    one_of,
    or_none,
    param,
)
from lac_rllib.constrained.lagrange import FixedMultiplierParams, initial_nu
from lac_rllib.constrained.minibatch_loop import UPDATE_PATHS
from lac_rllib.constrained.search_space import POLICY_LR, Searched, lr
from lac_rllib.constrained.task_config import SafeTaskConfig, SafeTaskParams

POLICY_LR_SCHEDULES = ("linear", "constant")
NU_PARAMETRIZATIONS = ("direct", "softplus")
NU_OPTIMIZERS = ("adam", "sgd")
ACTIVATIONS = ("tanh", "relu")
POSITIVE_OR_INF = Accepted("a number > 0 (inf: no clipping)", lambda v: isinstance(v, (int, float))
                           and not isinstance(v, bool) and v > 0)


@dataclasses.dataclass
class OnPolicyParams(SafeTaskParams):
    """The fields of the on-policy family built on RLlib's PPO (PPO-Lag and the first-order
    baselines on its house: FOCOPS, CUP, P3O, RESPO), after the fields every constrained algorithm
    has (:class:`SafeTaskParams`: its obs filter is [O]'s, std floored at 1e-2 and clipped at ±5).
    :class:`OnPolicyLagParams` adds the Lagrange multiplier's; each algorithm its preset and its own.

    Each field: ``name: type = param(default, accepts=...)`` and, below it, its docstring.
    """

    # --- episode cost ---
    cost_window: int | None = param(100, accepts=or_none(INT_GE_1))
    """Ĵ_C (ν's step; P3O's penalty): the mean cost of the last cost_window completed episodes [O
    window_lens 100]; None = of the episodes completed in this iteration only [S]. Checkpointed."""

    # --- advantages and critics ---
    cost_gamma: float = param(0.99, accepts=FRACTION)
    """γ_C of the cost GAE and the cost critic's target [O, S]; its λ is lambda_'s [O lam_c = lam; S]."""
    gamma: float = param(0.99, accepts=FRACTION)
    """γ of the reward GAE (RLlib's field) [O, S]."""
    lambda_: float = param(0.95, accepts=FRACTION)
    """λ of both GAEs (RLlib's field; its default is 1.0) [O lam, lam_c 0.95; S 0.97]."""
    standardize_cost_advantages: bool = param(False, accepts=BOOL)
    """A^C over the batch: centred only (False) [O standardized_cost_adv: mean only; S], so ν·A^C
    keeps the cost's scale; or centred and divided by its std (True) [F data_generator.py]."""
    critic_lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the reward and the cost critic, constant [O 3e-4; S vf_lr 1e-3]."""
    critic_l2: float = param(0.001, accepts=NON_NEGATIVE)
    """Weight of Σθ² over the critics' parameters in their loss, every minibatch [O critic_norm_coef; S: 0]."""
    vf_clip_param: float = param(float("inf"), accepts=POSITIVE_OR_INF)
    """RLlib's clamp of the *squared* value error (its default 10) [D: inf, no clamp, as O and S]: at 10
    it zeroes the gradient of every value more than √10 ≈ 3.2 off, as cost values (episode costs up
    to a limit of 25) often are."""

    # --- policy ---
    lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the policy at the start (RLlib's field; its default is 5e-5) [O, S]."""
    policy_lr_schedule: str = param("linear", accepts=one_of(POLICY_LR_SCHEDULES))
    """"linear": the policy's lr decays linearly to 0 over lr_decay_horizon env steps [O
    linear_lr_decay]; "constant": no decay [S]. The critics' lr is constant in both [O, S]."""
    lr_decay_horizon: int | None = param(None, accepts=or_none(INT_GE_1))
    """Env steps over which the policy's lr decays to 0 [O: its run's total_steps]; None = the run's
    own budget (total_env_steps). The Safety-Gym and MuJoCo presets set OmniSafe's 1e7
    (PPOLag.yaml), so a 2.5M run trains at the lr OmniSafe's benchmark run had at that step, not
    at an lr decayed to 0 by its own end (docs/baselines.md, "PPO-Lag's lr horizon")."""
    total_env_steps: int | None = param(None, accepts=or_none(INT_GE_1))
    """The run's budget in env steps (lac-train and the sweep set it): the linear decay's horizon
    where lr_decay_horizon is None."""
    target_kl: float | None = param(0.02, accepts=or_none(POSITIVE))
    """KL early stop [O 0.02]: after an epoch whose full-batch KL(π_old ‖ π) exceeds it, the policy
    takes no more steps this iteration (see kl_stop_late); None = off. [S] stops when KL > 1.2·0.01
    = 0.012, its KL the other way round, KL(π ‖ π_old) (here KL(π_old ‖ π) for both)."""
    kl_stop_late: bool = param(False, accepts=BOOL)
    """When the KL after an epoch exceeds target_kl: False, no further epoch trains the policy [O:
    it measures after an epoch and breaks]; True, one more epoch still does [S: it measures before
    a step and breaks after taking it]."""
    kl_stop_critics: bool = param(True, accepts=BOOL)
    """The KL stop also ends the critics' steps [O: it ends the whole update]; False: they run all
    num_epochs [S: the value function always takes its 80 steps]."""
    grad_clip: float | None = param(40.0, accepts=or_none(POSITIVE))
    """Global-norm gradient clip of each network (RLlib's field, applied per optimizer: policy,
    critic, cost critic) [O max_grad_norm 40]; None = off [S]."""
    hidden: tuple = param((64, 64), accepts=LAYERS)
    """Hidden layers of each of the three MLPs (policy, reward critic, cost critic) [O; S and the
    paper's App. D: (256, 256)]."""
    activation: str = param("tanh", accepts=one_of(ACTIVATIONS))
    """Activation of the MLPs [O, S]."""
    log_std_init: float = param(0.0, accepts=FINITE)
    """Initial state-independent log σ of the Gaussian policy [O gaussian_learning; S: −0.5]."""

    # --- data and schedule ---
    train_batch_size_per_learner: int = param(20_000, accepts=INT_GE_1)
    """Env steps sampled per iteration (RLlib's field) [O steps_per_epoch 20k; S 30k]."""
    num_epochs: int = param(40, accepts=INT_GE_1)
    """Passes over the iteration's batch (RLlib's field) [O update_iters 40; S train_pi_iters 80]."""
    minibatch_size: int | None = param(64, accepts=or_none(INT_GE_1))
    """Rows per gradient step (RLlib's field; phantom rows included, masked) [O batch_size 64];
    None = the whole batch per step [S]."""
    num_envs_per_env_runner: int = param(1, accepts=INT_GE_1)
    """Envs each env runner steps together (RLlib's field) [D]: the same episodes, cheaper per step."""
    torch_threads: int = param(1, accepts=INT_GE_1)
    """Intra-op torch threads of the learner process [D]; a sweep sets it to the CPUs of a trial."""
    update_path: str = param("fused", accepts=one_of(UPDATE_PATHS))
    """How an update call makes its steps [D]: "fused", its minibatches inside one learner
    ``_update`` with fewer calls per step (the same rows, order and maths, bit for bit;
    lac_rllib/constrained/minibatch_loop.py), or "rllib", RLlib's own path, one ``_update`` per
    minibatch (1.7x slower at OmniSafe's 64-row minibatches: docs/speed.md). Speed only."""


@dataclasses.dataclass
class OnPolicyLagParams(OnPolicyParams, FixedMultiplierParams):
    """The Lagrange multiplier's fields, after the on-policy family's (:class:`OnPolicyParams`)."""

    # --- Lagrange multiplier ---
    nu_init: float = param(0.001, accepts=NON_NEGATIVE)
    """ν₀ [O lagrangian_multiplier_init: 0.001; S penalty_init: 1]."""
    lagrangian_lr: float = param(0.035, accepts=NON_NEGATIVE)
    """Adam's learning rate for ν, one step per iteration before the policy update [O lambda_lr 0.035;
    S penalty_lr 0.05]. 0 pins ν at nu_init (so nu_init=0 with 0 is unconstrained PPO)."""
    nu_parametrization: str = param("direct", accepts=one_of(NU_PARAMETRIZATIONS))
    """"direct": Adam on ν, then ν ← max(ν, 0) [O common/lagrange.py]; "softplus": ν = softplus(p),
    Adam on the loss −p·(Ĵ_C − b) [S]."""
    nu_optimizer: str = param("adam", accepts=one_of(NU_OPTIMIZERS))
    """The step on ν's loss −ν·(Ĵ_C − b) (on p with "softplus") [O lambda_optimizer]: "adam" [O, S],
    or "sgd", eq. (14)'s plain step ν ← ν + lagrangian_lr·(Ĵ_C − b) [F focops_main.py] ("direct" only)."""
    nu_max: float | None = param(None, accepts=or_none(POSITIVE))
    """ν is held in [0, nu_max] after each step [O lagrangian_upper_bound: PPOLag.yaml sets none,
    FOCOPS.yaml and CUP.yaml 2.0]; None = no upper bound."""


OMNISAFE_BUDGET = 10_000_000  # env steps of OmniSafe's on-policy benchmark runs [O PPOLag.yaml total_steps]
#: The family's sizes per task preset: [O]'s defaults are the fields' own, its policy lr decaying
#: over its benchmark's budget; 10 and 5 envs split the 20k steps into whole 1000-step episodes
#: per env (speed only). An algorithm adds its own values (PPO-Lag's tiny ν, its ssa preset).
ON_POLICY_PRESETS: dict[str, dict[str, Any]] = {
    "safety_gym": {"num_envs_per_env_runner": 10, "lr_decay_horizon": OMNISAFE_BUDGET},
    "mujoco": {"num_envs_per_env_runner": 5, "lr_decay_horizon": OMNISAFE_BUDGET},
    # [D] lac/PointHazard-v0 (100-step episodes, limit 2) learns safely in 40k steps, ~30 s on one
    # core (tests/algorithms/ppo_lag/test_ppo_lag_learning.py): 2000 steps per iteration (20
    # episodes of 100 steps at first, ~100 once the agent reaches the goal in ~20), 10 epochs of 8
    # minibatches at lr 1e-3, and Ĵ_C on the last 20 episodes (one iteration's at first, a fifth of
    # one later), for a run of 20 iterations rather than hundreds.
    "tiny": {"train_batch_size_per_learner": 2000, "num_envs_per_env_runner": 10, "minibatch_size": 250,
             "num_epochs": 10, "lr": 1e-3, "critic_lr": 1e-3, "cost_window": 20},
}


class OnPolicyConfig(SafeTaskConfig, PPOConfig):
    """The on-policy family's config: an algorithm's config class extends it (or an algorithm's on
    it) with its ``PARAMS``, ``FIELDS``, ``PRESETS`` and learner; what the family declares for the
    CLI, the sweep and lac-eval is here, inherited."""

    REPORTED_KEYS = metrics.PPO_LAG_KEYS
    #: The family's searched fields, which each algorithm takes and adds its own to (in its order).
    SEARCH_SPACE = {
        "lr": lr(POLICY_LR),
        "clip_param": Searched("uniform", "Andrychowicz et al. 2021: PPO's clip 0.1-0.3", (0.1, 0.3)),
    }
    RL_MODULE_CLASS = "lac_rllib.families.on_policy.module.OnPolicyTorchRLModule"
    #: The mean action, or a draw from π (lac_rllib/evaluation.py ACTION_MODES).
    ACTIONS = ("generator", "stochastic")
    SPEED_FIELDS = frozenset({"num_envs_per_env_runner", "torch_threads", "update_path"})
    #: smoke at LAC's smoke sizes; quick on the paper's tasks 64-wide nets, one env, 2k-step
    #: iterations as LAC's (on the tiny task its own tiny preset is the quick budget).
    BUDGET_FIELDS = {
        "smoke": {"*": {"train_batch_size_per_learner": 500, "minibatch_size": 100, "num_epochs": 2,
                        "hidden": (32, 32), "num_envs_per_env_runner": 1}},
        "quick": {"tiny": {}, "*": {"train_batch_size_per_learner": 2_000, "hidden": (64, 64),
                                    "num_envs_per_env_runner": 1}},
    }

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
        # RLlib settings the family pins.
        self.use_kl_loss = False  # no adaptive KL penalty; the early stop bounds the step [O, S]
        self.entropy_coeff = 0.0  # [O entropy_coef, S ent_reg]
        self.vf_loss_coeff = 1.0  # plain MSE for both critics [O, S]
        self.grad_clip_by = "global_norm"  # [O clip_grad_norm_]
        self.shuffle_batch_per_epoch = True  # [O DataLoader(shuffle=True)]
        self.rollout_fragment_length = "auto"

    def policy_lr_or_schedule(self):
        """The policy's lr as RLlib's ``lr_or_lr_schedule``: [[0, lr], [horizon, 0]] in env steps
        (RLlib's Scheduler is stepped after each update with the lifetime env steps and holds 0
        past the horizon), or the constant."""
        if self.policy_lr_schedule == "constant":
            return self.lr
        return [[0, self.lr], [self.lr_horizon, 0.0]]

    @property
    def lr_horizon(self) -> int:
        """The env steps the policy's lr decays over: lr_decay_horizon, else the run's budget."""
        return int(self.lr_decay_horizon if self.lr_decay_horizon is not None else self.total_env_steps)

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict:
        """update_step.py: an iteration of 10·``steps`` env steps with the KL early stop off (every
        epoch makes all its minibatch steps)."""
        return {"train_batch_size_per_learner": 10 * steps, "target_kl": None} if benchmark == "update_step" else {}

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """Update seconds per env step on one CPU beyond sampling (measured at the tiny sizes)."""
        return 2e-4

    @classmethod
    def multiplier_warmup(cls, params: dict) -> int:
        """Ĵ_C (ν's step, P3O's penalty) is taken once per iteration from the first, on that
        iteration's episodes; it reaches the policy's update in the second: two iterations."""
        return 2 * int(params["train_batch_size_per_learner"])

    # ----- RLlib hooks -----
    @override(PPOConfig)
    def validate(self) -> None:
        super().validate()
        if getattr(self, "nu_optimizer", "adam") == "sgd" and self.nu_parametrization != "direct":
            raise ValueError(f"{self.FIELDS.what} config field nu_optimizer='sgd' is invalid with "
                             f"nu_parametrization={self.nu_parametrization!r}; accepted: nu_optimizer='adam', or "
                             "nu_parametrization='direct'")
        if self.policy_lr_schedule == "linear" and self.lr_decay_horizon is None and self.total_env_steps is None:
            raise ValueError(f"{self.FIELDS.what} config field total_env_steps=None is invalid with "
                             "policy_lr_schedule='linear' and no lr_decay_horizon (the decay needs a horizon); "
                             "accepted: an integer >= 1, an lr_decay_horizon, or policy_lr_schedule='constant'")

    @override(AlgorithmConfig)
    def build_learner_connector(self, input_observation_space, input_action_space, device=None):
        """RLlib's learner pipeline plus the cost of each row (PPOLearner.build then prepends the
        phantom step and appends the GAEs, learner.py)."""
        pipeline = super().build_learner_connector(
            input_observation_space=input_observation_space, input_action_space=input_action_space, device=device)
        pipeline.insert_after(AddColumnsFromEpisodesToTrainBatch,
                              AddCostsFromInfos(constraints=self.constraints_data()))
        return pipeline

    @property
    @override(PPOConfig)
    def _model_config_auto_includes(self) -> dict[str, Any]:
        return {**super()._model_config_auto_includes,
                "fcnet_hiddens": list(self.hidden), "fcnet_activation": self.activation, "head_fcnet_hiddens": [],
                "vf_share_layers": False, "free_log_std": True, "log_std_init": self.log_std_init,
                # no multiplier (P3O, CPO, PCPO): ν stays 0
                "nu_init": initial_nu({"nu_init": getattr(self, "nu_init", 0.0),
                                       "nu_fixed": getattr(self, "nu_fixed", None)}),
                "normalize_actions": self.normalize_actions,
                # several constraints: a cost critic and a multiplier each (absent: one); the frontier
                # along one of them: ν₀ nu_fixed for the one it holds, nu_init for the others
                **({"num_constraints": self.num_constraints} if self.num_constraints > 1 else {}),
                **({"nu_init": float(self.nu_init), "nu_fixed": self.nu_fixed, **self.nu_fixed_model_config()}
                   if self.nu_fixed_model_config() else {})}
