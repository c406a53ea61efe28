"""SACLagConfig: SAC-Lagrangian's fields, each declared once with its default and source.

SAC-Lag is a baseline of ours (the paper has none), built on LAC's skeleton and following OmniSafe's
``SACLag`` (``algorithms/off_policy/sac_lag.py`` on ``sac.py``/``ddpg.py``, ``configs/off-policy/
SACLag.yaml``; the design and its deviations: docs/baselines.md). Fields live in
:class:`SACLagParams`; ``SACLagConfig`` copies them onto itself, checks each as it is set and
exposes the same module-level names as every algorithm (lac_rllib/algorithms/registry.py).
Source tags: [O] OmniSafe, [F] FSRL, [D] ours.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.utils.annotations import override

from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.costs import DrawRows
from lac_rllib.constrained.fields import (
    BOOL,
    FINITE,
    FRACTION,
    INT_GE_0,
    INT_GE_1,
    LAYERS,
    NON_NEGATIVE,
    POSITIVE,
    one_of,
    or_none,
    param,
)
from lac_rllib.constrained.lagrange import FixedMultiplierParams
from lac_rllib.constrained.minibatch_loop import UPDATE_PATHS
from lac_rllib.constrained.networks import ACTIVATIONS
from lac_rllib.constrained.precision import DTYPE_CHOICES, resolve_dtype
from lac_rllib.constrained.search_space import MULTIPLIER_LR, lr
from lac_rllib.constrained.task_config import SafeTaskParams
from lac_rllib.families.off_policy.config import OffPolicyConfig

LAGRANGIAN_RULES = ("adam", "gradient")
#: critic_dtype="auto" runs bfloat16 only on critics at least this wide: below, the casts cost
#: more than the matmuls save (a PointGoal1 step at 64 wide: 3.55 ms float32, 4.19 bfloat16; at
#: 128: 8.64 / 7.22; at 256: 15.43 / 9.86; docs/speed.md).
BF16_MIN_WIDTH = 128
MINIBATCH_DRAWS = ("with_replacement", "shuffled_passes")


@dataclasses.dataclass
class SACLagParams(SafeTaskParams, FixedMultiplierParams):
    """The SAC-Lag hyperparameters, after the fields every constrained algorithm has
    (:class:`SafeTaskParams`). Defaults are OmniSafe's SACLag.yaml defaults (its MuJoCo column).

    Each field: ``name: type = param(default, accepts=...)`` and, below it, its docstring.
    """

    # --- losses ---
    alpha: float = param(0.2, accepts=NON_NEGATIVE)
    """α, the fixed entropy coefficient in the reward target and the actor loss [O: auto_alpha off]."""
    cost_gamma: float = param(0.99, accepts=FRACTION)
    """γ_C, the discount of the cost critic's target [O: the same γ as the reward's, 0.99]."""

    # --- actor ---
    actor_lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the actor [O], constant [O: linear_lr_decay off]."""
    actor_hidden: tuple = param((256, 256), accepts=LAYERS)
    """Hidden layers of the actor MLP (obs → μ, log σ) [O]."""
    log_std_min: float = param(-20.0, accepts=FINITE)
    """Lower clamp of the actor's log σ(s) [O]."""
    log_std_max: float = param(2.0, accepts=FINITE)
    """Upper clamp of the actor's log σ(s) [O]."""

    # --- critics ---
    critic_lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the two reward critics and the cost critic [O]."""
    critic_hidden: tuple = param((256, 256), accepts=LAYERS)
    """Hidden layers of each critic (obs+act → MLP → Q) [O]."""
    activation: str = param("relu", accepts=one_of(ACTIVATIONS))
    """Activation of the actor and the critics [O]."""
    critic_dtype: str = param("float32", accepts=one_of(DTYPE_CHOICES))
    """Input dtype of the critics' hidden-layer matmuls, in the update and its targets [D]:
    "float32", "bfloat16" (the output layer, the parameters, their gradients and Adam stay
    float32), or "auto" = bfloat16 on a CPU with native bf16 matmuls (AVX512-BF16, AMX) and
    critics at least ``BF16_MIN_WIDTH`` wide, float32 otherwise, decided where the module is built
    and recorded as what it resolved to (config.json's ``resolved``, the checkpoint's metadata, the
    MLflow tag ``lac.resolved.critic_dtype``; a resume where it resolves otherwise is refused). The
    critics are most of a step's matmuls at (256, 256), so bfloat16 makes the PointGoal1 step
    ~1.5x faster on such a CPU (docs/speed.md). float32 is OmniSafe's arithmetic and the default;
    "auto" in the ``safety_gym`` preset, where its PointGoal1 curves matched float32's at equal
    seeds (docs/fidelity/pointgoal1-sac-lag/)."""
    max_grad_norm: float | None = param(40.0, accepts=or_none(POSITIVE))
    """Global gradient-norm clip of each network: the reward critics, the cost critic, the actor
    [O]; None = off."""
    polyak_tau: float = param(0.005, accepts=FRACTION)
    """Polyak τ of both target critics [O: polyak]."""
    policy_delay: int = param(2, accepts=INT_GE_1)
    """The actor step and Polyak happen on every policy_delay-th gradient step only [O]."""

    # --- Lagrange multiplier ---
    nu_init: float = param(0.001, accepts=NON_NEGATIVE)
    """λ₀, the multiplier at the start [O: lagrangian_multiplier_init]."""
    lagrangian_rule: str = param("adam", accepts=one_of(LAGRANGIAN_RULES))
    """"adam": Adam on −λ·(Ĵ_C − b), then λ ≥ 0 [O]; "gradient": λ + lr·(Ĵ_C − b), LAC's eq. (14) [D]."""
    lagrangian_lr: float = param(1e-5, accepts=NON_NEGATIVE)
    """The learning rate of λ's rule [O: lambda_lr]; 0 pins λ at λ₀."""
    warmup_env_steps: int = param(200_000, accepts=INT_GE_0)
    """λ takes no step until more env steps than this are sampled [O: warmup_epochs 100 × 2000 steps]."""
    cost_window: int = param(10, accepts=INT_GE_1)
    """Ĵ_C is the mean cost of the last cost_window completed episodes [O: logger window_lens]."""

    # --- data and schedule ---
    env_steps_per_iteration: int = param(2000, accepts=INT_GE_1)
    """Env steps sampled per iteration, then trained on in one update call [D]. OmniSafe updates
    after every env step; here the policy is fixed within an iteration (the price of paying
    RLlib's per-call overhead once per iteration)."""
    num_envs_per_env_runner: int = param(1, accepts=INT_GE_1)
    """Envs each env runner steps together (RLlib's own field) [D]."""
    updates_per_env_step: float = param(1.0, accepts=POSITIVE)
    """Gradient steps per new env step: an iteration makes updates_per_env_step × its env steps
    [O: update_cycle = update_iters = 1]."""
    batch_size: int = param(256, accepts=INT_GE_1)
    """Minibatch size of each gradient step [O]."""
    minibatch_draws: str = param("with_replacement", accepts=one_of(MINIBATCH_DRAWS))
    """"with_replacement": each minibatch is batch_size rows drawn uniformly from the whole buffer
    [O offpolicy_buffer.py sample_batch]; "shuffled_passes": the iteration's minibatches are cut
    from shuffled passes over the buffer, reshuffled at each wrap (no row twice before every row
    once; this implementation's draw before the field existed)."""
    replay_capacity: int = param(1_000_000, accepts=INT_GE_1)
    """Replay buffer capacity in env steps [O: size]."""
    random_env_steps: int = param(10_000, accepts=INT_GE_0)
    """Iterations act uniformly at random while fewer env steps than this are sampled, and make no
    gradient step before the first iteration that reaches it [O: start_learning_steps]."""
    store_replay_buffer: bool = param(True, accepts=BOOL)
    """Keep the replay buffer in checkpoints [D], so a resumed run trains on the data it had."""
    torch_threads: int = param(1, accepts=INT_GE_1)
    """Intra-op torch threads of the learner process [D]; a sweep sets it to the CPUs of a trial."""
    flush_denormal: bool = param(False, accepts=BOOL)
    """Flush denormal floats to zero in the learner's process [D] (``torch.set_flush_denormal``).
    Adam's moments and their squared gradients pass through denormals, which x86 CPUs compute
    slowly: on an Intel Xeon with AMX the PointGoal1 step's fused Adam took 1.9 ms in the learner
    against 0.24 ms on fresh data, and flushing took the step from 8.7-9.0 to 7.2-7.8 ms (PPO-Lag's:
    ~2%). It changes bits (values below ~1.2e-38 become 0): at equal seeds on PointGoal1 the runs
    repeat the default's exactly through 124-158k env steps, then part as seeds do, in 1.35x less
    wall time (docs/fidelity/pointgoal1-sac-lag-flush); False until a run past 200k, where ν acts,
    shows the same."""
    update_path: str = param("fused", accepts=one_of(UPDATE_PATHS))
    """How an update call makes its steps [D]: "fused", its minibatches inside one learner
    ``_update`` with fewer calls per step (the same rows, order and maths, bit for bit;
    lac_rllib/constrained/minibatch_loop.py), or "rllib", RLlib's own path, one ``_update`` per
    minibatch (1.0-1.1x slower: SAC-Lag's step is its matmuls: docs/speed.md). Speed only."""


def critic_matmul_dtype(critic_dtype: str, critic_hidden) -> str:
    """What ``critic_dtype`` runs as on this CPU: "auto" is bfloat16 where the CPU multiplies it
    natively (lac_rllib.constrained.precision.resolve_dtype) and the narrowest hidden layer is at
    least ``BF16_MIN_WIDTH`` wide, float32 otherwise; an explicit dtype is kept."""
    if critic_dtype == "auto" and min(critic_hidden, default=0) < BF16_MIN_WIDTH:
        return "float32"
    return resolve_dtype(critic_dtype)


# [O] SACLag.yaml: its defaults (the MuJoCo column); its Goal1/Circle1 overrides for the
# navigation tasks; obs_normalize False everywhere. "tiny" [D] learns lac/PointHazard-v0 within
# the limit in ~20k env steps (tests/algorithms/sac_lag/test_sac_lag_learning.py): small nets,
# short warm-ups, α small enough that the entropy bonus (up to ~α·1.4 a step) does not outweigh
# the step penalty 0.1, and a λ learning rate at which Adam (steps of ~lr) moves λ by ~1 per
# 1000-step iteration, fast enough to act within the run.
PRESETS: dict[str, dict[str, Any]] = {
    "mujoco": {"obs_normalization": False},
    "safety_gym": {"obs_normalization": False, "alpha": 1e-5, "actor_lr": 5e-6, "critic_lr": 1e-3,
                   "nu_init": 0.0, "lagrangian_lr": 5e-7, "critic_dtype": "auto"},
    "tiny": {
        "obs_normalization": False,
        "env_steps_per_iteration": 1000,
        "num_envs_per_env_runner": 10,
        "actor_hidden": (64, 64),
        "critic_hidden": (64, 64),
        "replay_capacity": 50_000,
        "random_env_steps": 2000,
        "alpha": 0.01,
        "nu_init": 0.0,
        "lagrangian_lr": 1e-3,
        "warmup_env_steps": 5000,
    },
}

#: SAC-Lag's fields and what each accepts (lac_rllib/algorithms/registry.py).
FIELDS = fields.FieldSet(SACLagParams, "SAC-Lag")


class SACLagConfig(OffPolicyConfig, AlgorithmConfig):
    """Config for :class:`lac_rllib.algorithms.sac_lag.algorithm.SACLag`; the fields are
    :class:`SACLagParams`'. ``SACLagConfig().task(id)`` sets the env, its cost convention and the
    task's preset; explicit ``training(...)`` values win over the preset."""

    SEVERAL_CONSTRAINTS = True  # a cost critic and a λ each (OmniSafe's Adam step per constraint)

    ALGO = "sac_lag"
    OMNISAFE_NAME = "SACLag"  # its implementation in OmniSafe 0.5.0 (benchmarks/peers.py)
    PARAMS, FIELDS, PRESETS = SACLagParams, FIELDS, PRESETS
    SEARCH_SPACE = {
        "actor_lr": lr("[O] SACLag.yaml's actor lr spans 5e-6 to 3e-4 across task families"),
        "critic_lr": lr("[O] SACLag.yaml's critic lr spans 3e-4 to 1e-3 across task families"),
        "alpha": lr("[O] SACLag.yaml's entropy weight spans 1e-5 to 0.2 across task families"),
        "lagrangian_lr": lr(MULTIPLIER_LR),
    }
    #: What ``lac-eval --actions`` accepts: squash(μ(s)) (module.deterministic_action), or a draw from π.
    ACTIONS = ("generator", "stochastic")
    SPEED_FIELDS = frozenset({"num_envs_per_env_runner", "torch_threads", "update_path"})
    #: smoke at LAC's smoke sizes; quick on the paper's tasks 64-wide nets, one env, 2k-step
    #: iterations as LAC's (on the tiny task its own tiny preset is the quick budget).
    BUDGET_FIELDS = {
        "smoke": {"*": {"env_steps_per_iteration": 500, "replay_capacity": 2_000, "random_env_steps": 500,
                        "warmup_env_steps": 500, "actor_hidden": (32, 32), "critic_hidden": (32, 32),
                        "num_envs_per_env_runner": 1}},
        "quick": {"tiny": {}, "*": {"env_steps_per_iteration": 2_000, "replay_capacity": 10_000,
                                    "random_env_steps": 2_000, "actor_hidden": (64, 64), "critic_hidden": (64, 64),
                                    "num_envs_per_env_runner": 1}},
    }

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict:
        """update_step.py: 2,000 random env steps and then iterations of ``steps`` (one gradient step
        each); iteration.py: the random steps within the warm-up of ``steps``."""
        if benchmark == "update_step":
            return {"random_env_steps": 2000, "env_steps_per_iteration": steps}
        return {"random_env_steps": steps // 2}

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """Update seconds per env step on one CPU beyond sampling (the plan's estimate, measured at the
        tiny sizes): per gradient update, times the updates per env step."""
        return 2e-3 * params.get("updates_per_env_step", 1.0)

    @classmethod
    def multiplier_warmup(cls, params: dict) -> int:
        """λ takes no step before ``warmup_env_steps`` [O] (early stopping waits for it)."""
        return int(params["warmup_env_steps"])
    REPORTED_KEYS = (metrics.CRITIC_LOSS, metrics.ACTOR_LOSS, metrics.Q_REWARD_MEAN, metrics.Q_COST_MEAN,
                     metrics.COST_WINDOW_MEAN)
    ALGORITHM_CLASS = "lac_rllib.algorithms.sac_lag.algorithm.SACLag"
    RL_MODULE_CLASS = "lac_rllib.algorithms.sac_lag.module.SACLagTorchRLModule"
    LEARNER_CLASS = "lac_rllib.algorithms.sac_lag.learner.SACLagTorchLearner"
    MINIBATCH_FIELD = "batch_size"

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
        # RLlib fields with SAC-Lag's values.
        self.gamma = 0.99  # [O]
        # The squashed Gaussian acts within the bounds and random actions come from the action
        # space: both are stored in the env's units, as the critics see them.
        self.clip_actions = False
        self.normalize_actions = False

    # ----- RLlib hooks -----
    @override(AlgorithmConfig)
    def validate(self) -> None:
        super().validate()
        if self.log_std_min >= self.log_std_max:
            raise ValueError(f"SAC-Lag config fields log_std_min={self.log_std_min!r} and log_std_max="
                             f"{self.log_std_max!r} are invalid together; accepted: log_std_min < log_std_max")

    def resolved(self) -> dict[str, Any]:
        """``critic_dtype`` as the critics run it here (:func:`critic_matmul_dtype`)."""
        return {"critic_dtype": critic_matmul_dtype(self.critic_dtype, self.critic_hidden)}

    @property
    def updates_per_iteration(self) -> int:
        """The gradient steps of an iteration that samples env_steps_per_iteration env steps."""
        return max(1, round(self.updates_per_env_step * self.env_steps_per_iteration))

    @override(OffPolicyConfig)
    def minibatch_rows(self):
        """The iteration's minibatch rows: drawn with replacement (minibatch_draws, OmniSafe's
        draw), or the buffer's rows shuffled."""
        if self.minibatch_draws == "with_replacement":
            return DrawRows(rows=self.updates_per_iteration * self.batch_size, seed=self.seed)
        return super().minibatch_rows()

    @property
    @override(AlgorithmConfig)
    def _model_config_auto_includes(self) -> dict[str, Any]:
        # The module needs the network sizes, the log σ clamp and λ₀.
        return {**super()._model_config_auto_includes, **self.params()}
