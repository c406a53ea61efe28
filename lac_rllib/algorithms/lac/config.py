"""LACConfig: every field of ``docs/spec.md`` declared once, with its default and source.

Fields live in the :class:`LACParams` dataclass below, one docstring each; ``LACConfig`` copies
them onto itself, so ``config.langevin_steps`` works like any RLlib field and
``config.training(langevin_steps=50)`` sets it. Each field declares its accepted values next to
its default (:class:`Accepted`); they are checked as they are set, so bad input fails before Ray
starts, and docs/config.md and ``lac-train --help`` show them. Source tags: [P] paper, [C]
authors' code, [F] FOCOPS, [D] ours.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.lac.langevin import CLIP_MODES, INFORMATIVE, STARTS
from lac_rllib.constrained import fields, metrics
from lac_rllib.constrained.cpus import check_cpus, run_resources, runner_cpus, set_runners, use_cpus  # noqa: F401
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
from lac_rllib.constrained.networks import ACTIVATIONS
from lac_rllib.constrained.precision import DTYPE_CHOICES as LANGEVIN_DTYPES
from lac_rllib.constrained.precision import resolve_dtype
from lac_rllib.constrained.search_space import MULTIPLIER_LR, Searched, lr
from lac_rllib.constrained.task_config import SafeTaskParams
from lac_rllib.families.off_policy.config import OffPolicyConfig

CHAIN_AT = ("next", "current")
LR_SCHEDULES = ("linear", "constant")


@dataclasses.dataclass
class LACParams(SafeTaskParams, FixedMultiplierParams):
    """The LAC hyperparameters (docs/spec.md §1-5), after the fields every constrained algorithm has
    (:class:`SafeTaskParams`). Defaults are the MuJoCo column of docs/spec.md §5.

    Each field: ``name: type = param(default, accepts=...)`` and, below it, its docstring.
    """

    # --- Langevin chain (docs/spec.md §1, Algorithm 1) ---
    langevin_steps: int = param(30, accepts=INT_GE_1)
    """T, Langevin steps per chain [P Tables 4-5]."""
    langevin_step_size: float = param(1e-4, accepts=POSITIVE)
    """η, the step size of eq. (9) [P]."""
    temperature: float = param(1e-3, accepts=POSITIVE)
    """λ, the fixed temperature of the energy [P Tables 4-5]; the safety_gym preset uses [C]'s 1e-4,
    which learned better on PointGoal1 (docs/spec.md §1, docs/fidelity/)."""
    langevin_start: str = param(INFORMATIVE, accepts=one_of(STARTS))
    """"informative": ã₀ ~ π_φ'(·|s) (eq. 11) [P, C]; "noninformative": ã₀ ~ N(0, I) (ablation NI)."""
    logp_weight: float = param(1.0, accepts=NON_NEGATIVE)
    """w, the weight of −log π_φ' in the energy [P; C's flag is pinned to 1 by a bug]."""
    langevin_clamp: bool = param(True, accepts=BOOL)
    """Clamp ã to the action bounds after every step [C]."""
    langevin_grad_clip: float | None = param(1000.0, accepts=or_none(POSITIVE))
    """Clip of ∇_a E at every chain step [C: 1000]; None = off. On by default because [C] clips and
    the clip shapes where the chain's end points land late in a run (when it binds and what it
    prevents: docs/spec.md §1, docs/fidelity/)."""
    langevin_grad_clip_mode: str = param("batch", accepts=one_of(CLIP_MODES))
    """"batch": one L2 norm over the whole minibatch's ∇_a E (B × A) [C]; "per_sample": each
    sample's gradient clipped to langevin_grad_clip/√B, the same step when gradients are alike
    without coupling unrelated samples [D]."""
    langevin_fused: bool = param(True, accepts=BOOL)
    """Each chain step's energy gradient through torch.compile, which fuses the element-wise work
    of every critic layer [D]: the same maths to float rounding, faster at the paper's sizes for a
    one-off compile per process (figures: docs/speed.md). False: the eager hand-written backward;
    it is also the fallback, with a warning, where compiling fails."""
    langevin_dtype: str = param("float32", accepts=one_of(LANGEVIN_DTYPES))
    """Input dtype of the chain's critic matmuls (action, energy and update stay float32) [D]:
    "float32", "bfloat16", or "auto" = bfloat16 on a CPU with native bf16 matmuls (AVX512-BF16,
    AMX), float32 elsewhere, decided where the module is built and recorded as what it resolved to
    (config.json's ``resolved``, the checkpoint's metadata, the MLflow tag
    ``lac.resolved.langevin_dtype``; a resume where it resolves otherwise is refused). float32 by
    default, "auto" in the ``safety_gym`` preset, where its learning curves matched float32's
    (docs/fidelity/pointgoal1-bf16/); bfloat16 is far slower without native support
    (docs/speed.md); its end points differ from float32's by far less than the chain's
    own noise (tests/algorithms/lac/test_energy.py)."""

    # --- critics (docs/spec.md §2, eqs. 12-13) ---
    cost_gamma: float = param(0.99, accepts=FRACTION)
    """γ_C, cost discount in the cost critic's target [C; D: γ_C = 1 leaves Q_C unbounded]."""
    reward_scale: float = param(10.0, accepts=NON_NEGATIVE)
    """k_r, multiplies the reward in the reward critic's target [C]; cost is unscaled."""
    bootstrap_on_truncation: bool = param(True, accepts=BOOL)
    """Bootstrap through time-limit truncation [D]; False treats it as terminal, like [C]."""
    critic_lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the four critics at the start of the run [P]."""
    critic_hidden: tuple = param((256, 256, 256), accepts=LAYERS)
    """Hidden layers of each critic (obs+act → Mish MLP → Q) [C]."""

    # --- actor (docs/spec.md §3, eqs. 15-16) ---
    beta: float = param(0.0, accepts=NON_NEGATIVE)
    """β, weight of KL(π_φ ‖ π_φ') in the actor loss eq. (16) [C: 0; P Table 3 "PR"]."""
    actor_chain_at: str = param("next", accepts=one_of(CHAIN_AT))
    """Where the actor's target chain runs: "next" reuses the critic chain at s' [C];
    "current" runs a second chain at s as eq. (15) writes [P]."""
    actor_lr: float = param(3e-4, accepts=POSITIVE)
    """Adam learning rate of the generator actor at the start of the run [P]."""
    actor_grad_clip: float | None = param(40.0, accepts=or_none(POSITIVE))
    """Global gradient-norm clip of the actor [C]; None = off."""
    actor_update_start_iteration: int = param(1, accepts=INT_GE_0)
    """First training iteration (0-based) whose minibatches update the actor [C: after the first]."""
    actor_hidden: tuple = param((256, 256), accepts=LAYERS)
    """Hidden layers of the Gaussian generator actor [P Tables 4-5]."""
    actor_activation: str = param("tanh", accepts=one_of(ACTIVATIONS))
    """Activation of the actor MLP [P Tables 4-5]."""
    log_std_init: float = param(-0.5, accepts=FINITE)
    """Initial state-independent log-std of the actor [P Tables 4-5]."""
    actor_mean_init_scale: float | None = param(0.1, accepts=or_none(POSITIVE))
    """The actor's mean-head weights are multiplied by this at init and its bias zeroed [C], so
    the first policy acts near 0; None keeps nn.Linear's init of the head."""

    # --- Lagrange multiplier (docs/spec.md §4, eq. 14) ---
    nu_init: float = param(0.0, accepts=NON_NEGATIVE)
    """ν₀, the Lagrange multiplier at the start [P, C]."""
    nu_lr: float = param(0.01, accepts=NON_NEGATIVE)
    """α_ν, step of the projected ν update eq. (14) [P, C]; 0 pins ν at ν₀."""
    nu_max_adaptive: bool = param(True, accepts=BOOL)
    """Upper bound on ν [C]: 2 in the first iteration, then 2·|mean y_R| / |mean y_C| over the
    latest iteration's minibatches, so the cost term cannot take over the chain while the reward
    critic is small (docs/spec.md §4). False: ν unbounded, as [P] writes eq. (14)."""

    # --- data and schedule (docs/spec.md §5) ---
    env_steps_per_iteration: int = param(5000, accepts=INT_GE_1)
    """Env steps sampled per iteration ("batch size" in Tables 4-5) [P]."""
    replay_capacity: int = param(50_000, accepts=INT_GE_1)
    """Replay buffer capacity in env steps [P, C]."""
    lac_minibatch_size: int = param(256, accepts=INT_GE_1)
    """Minibatch size of the gradient steps [P]."""
    gradient_passes: float = param(1.0, accepts=POSITIVE)
    """Passes over the buffer per iteration ("1 epoch") [P, C]: ≈ buffer/minibatch steps."""
    polyak_tau: float = param(0.005, accepts=FRACTION)
    """Polyak τ for all target networks, applied after every gradient step [C]."""
    polyak_from_actor_start: bool = param(True, accepts=BOOL)
    """Polyak updates begin with the first actor update (actor_update_start_iteration) [C];
    False: from the first gradient step."""
    lr_schedule: str = param("linear", accepts=one_of(LR_SCHEDULES))
    """"linear": both learning rates decay linearly from their start to lr_final_fraction × start
    over lr_decay_horizon env steps [C], through RLlib's lr schedules; "constant": no decay."""
    lr_final_fraction: float = param(0.5, accepts=FRACTION)
    """The learning rates at the end of the budget, as a fraction of their start [C: 0.5]."""
    lr_decay_horizon: int | None = param(None, accepts=or_none(INT_GE_1))
    """Env steps over which the linear decay runs to lr_final_fraction [C: its whole budget]; None =
    the run's own budget (total_env_steps). The Safety-Gym and MuJoCo presets set the paper's 2.5M,
    so a shorter run decays part way, as [C]'s would at that step (docs/spec.md §5)."""
    total_env_steps: int | None = param(None, accepts=or_none(INT_GE_1))
    """The run's budget in env steps: lac-train and the sweep set it from theirs. The lr decay's
    horizon where lr_decay_horizon is None."""
    num_envs_per_env_runner: int = param(1, accepts=INT_GE_1)
    """Envs each env runner steps together (RLlib's own field, a gymnasium SyncVectorEnv) [D]:
    RLlib's per-step work (connectors, episode bookkeeping) is then paid once per batch of envs
    instead of once per step. The policy is fixed within an iteration, so this changes only which
    episode segments an iteration holds; the presets choose counts whose iterations still complete
    whole episodes (docs/speed.md, with the figures)."""
    random_iterations: int = param(5, accepts=INT_GE_0)
    """Iterations that act uniformly at random before the generator takes over [C]."""
    store_replay_buffer: bool = param(True, accepts=BOOL)
    """Keep the replay buffer in checkpoints [D; RLlib's store_buffer_in_checkpoints], so a resumed
    or retried run trains on the data it had, not on an empty buffer; False keeps checkpoints
    small (a full PointGoal1 buffer is tens of MB)."""
    torch_threads: int = param(1, accepts=INT_GE_1)
    """Intra-op torch threads of the learner process [D]: 1, because minibatch tensors are small and
    extra threads only add synchronisation on a shared machine (docs/speed.md). A sweep sets it to
    the CPUs of a trial."""


# Table 4 (MuJoCo) and Table 5 (Safety Gym), docs/spec.md §5. "tiny" [D] sizes lac/PointHazard-v0
# to learn in about a minute on 2 cores: small nets, short chains, a larger α_ν for its ten times
# smaller cost limit, no chain clip (why each, measured: docs/spec.md §5, "The tiny preset").
PAPER_BUDGET = 2_500_000  # env steps of every paper task [P]; [C]'s lr decay horizon (125 × 20k)
PRESETS: dict[str, dict[str, Any]] = {
    "mujoco": {"env_steps_per_iteration": 5000, "num_envs_per_env_runner": 5, "lr_decay_horizon": PAPER_BUDGET},
    # λ = 1e-4 as [C] runs the Safety-Gym tasks; Table 5's 1e-3 learned less on PointGoal1 at
    # equal seeds (docs/fidelity/pointgoal1-lambda/). The chain in bfloat16 where the CPU has native
    # bf16 matmuls: on PointGoal1 its curves matched float32's at equal seeds (3 seeds to 500k,
    # docs/fidelity/pointgoal1-bf16/) and its runs took 0.6-0.8x the time.
    "safety_gym": {"env_steps_per_iteration": 20_000, "num_envs_per_env_runner": 10,
                   "lr_decay_horizon": PAPER_BUDGET, "temperature": 1e-4, "langevin_dtype": "auto"},
    "tiny": {
        "env_steps_per_iteration": 1000,
        "replay_capacity": 10_000,
        "langevin_steps": 10,
        "actor_hidden": (64, 64),
        "critic_hidden": (64, 64),
        "random_iterations": 2,
        "nu_lr": 0.03,
        "langevin_grad_clip": None,
        # A compile costs more than a tiny run's whole chain time.
        "langevin_fused": False,
    },
}


#: LAC's fields and what each accepts.
FIELDS = fields.FieldSet(LACParams, "LAC")


# A trial this short cannot repay a compile of the fused chain (~15-40 s per process): eager.
_SMOKE = {"env_steps_per_iteration": 500, "replay_capacity": 2_000, "random_iterations": 1,
          "actor_hidden": (32, 32), "critic_hidden": (32, 32), "num_envs_per_env_runner": 1, "langevin_fused": False}
#: The fields a sweep's named budget sets (sweeps/spaces.py BUDGETS), per task preset ("*": any other).
#: quick on the tiny task is the default ablation's (docs/sweeps.md): T = 20, the fused chain (it
#: pays there: a T = 30 trial runs ~1,400 chains of 30 steps, the compiled kernels cached on disk
#: across trials) and ten envs per runner (RLlib's per-step machinery took 55% of a one-env trial,
#: py-spy; ten 100-step episodes still complete in every 1,000-step iteration). On the paper's
#: tasks quick is a machinery check: 64-wide nets, one env so 2k-step iterations complete
#: 1000-step episodes.
LAC_BUDGET_FIELDS = {
    "smoke": {"*": _SMOKE},
    "quick": {"tiny": {"langevin_steps": 20, "langevin_fused": True, "num_envs_per_env_runner": 10},
              "*": {"env_steps_per_iteration": 2_000, "replay_capacity": 10_000, "random_iterations": 1,
                    "gradient_passes": 0.5, "actor_hidden": (64, 64), "critic_hidden": (64, 64),
                    "num_envs_per_env_runner": 1, "langevin_fused": False}},
}
#: The chain's seconds per env step and per Langevin step on one CPU, per preset (the plan's
#: estimate; calibration: docs/sweeps.md).
CHAIN_S_PER_STEP = {"tiny": 4.1e-5, "safety_gym": 1.37e-4, "mujoco": 5.3e-4}



class LACConfig(OffPolicyConfig, AlgorithmConfig):
    """Config for :class:`lac_rllib.algorithms.lac.algorithm.LAC`. See :class:`LACParams` for the fields.

    ``LACConfig().task("SafetyPointGoal1-v0")`` sets the env, its cost convention and the
    task's preset (docs/spec.md §5, Tables 4-5); explicit ``training(...)`` values win over presets.
    """

    ALGO = "lac"
    PARAMS, FIELDS, PRESETS = LACParams, FIELDS, PRESETS
    #: K constraints: twin cost critics and a ν_k (eq. 14, its own adaptive bound) each; the chain's
    #: energy weighs Σ_k ν_k·max_j Q_Ckj (lac_rllib/algorithms/lac/energy.py).
    SEVERAL_CONSTRAINTS = True
    #: LAC's four: the chain's length T, step size η, temperature λ, KL weight β. The paper's Table 3
    #: varies T and β only; η and λ are fixed by its Tables 4-5, so they are searched a decade either
    #: side of the task's default on a log scale (its default at the centre: this project's
    #: safety_gym preset runs λ = 1e-4, an absolute [1e-4, 1e-2] put it at the lower edge). β takes
    #: the paper's own values: uniform on [0, 20] put half the draws at β >= 10, where the actor
    #: barely moves at the quick budget (docs/tuned-pointhazard: 7 of 8 draws), and never drew the
    #: default 0.
    SEARCH_SPACE = {
        "langevin_steps": Searched("int", "[P] Table 3's VT runs T in {10, 20, 30, 40, 50, 100}; Algorithm 1's "
                                          "chain length", (10, 100)),
        "langevin_step_size": Searched("loguniform", "[P] Tables 4-5 fix η = 1e-4 (Algorithm 1's step; Table 3 "
                                                     "does not vary it): a decade either side", around=10.0),
        "temperature": Searched("loguniform", "[P] Tables 4-5 fix λ = 1e-3 (eq. 9's temperature; Table 3 does "
                                              "not vary it): a decade either side", around=10.0),
        "beta": Searched("choice", "[P] Table 3's PR runs β in {0, 1, 5, 10, 20} (the actor's KL weight; "
                                   "Appendix D.1, Figure 6)", (0.0, 1.0, 5.0, 10.0, 20.0)),
    }
    #: PBT changes the four and the rates mid-run (sweeps/pbt.py): the Adam rates a decade either side
    #: of the task's default, as every algorithm's, and ν's step α_ν as every multiplier's rate.
    CHANGEABLE = {
        **SEARCH_SPACE,
        "actor_lr": lr("[P] Tables 4-5: one Adam rate per task family; a decade either side"),
        "critic_lr": lr("[P] Tables 4-5: one Adam rate per task family; a decade either side"),
        "nu_lr": lr(MULTIPLIER_LR),
    }
    #: What ``lac-eval --actions`` accepts for a LAC policy: the generator's mean, a draw from it,
    #: or Algorithm 1's chain.
    ACTIONS = ("generator", "stochastic", "langevin")
    SPEED_FIELDS = frozenset({"langevin_fused", "num_envs_per_env_runner", "torch_threads"})
    BUDGET_FIELDS = LAC_BUDGET_FIELDS
    #: Table 5 sets T = 50 Langevin steps on the Button1 tasks; we apply it to the whole Button
    #: family (levels 0-2, TaskSpec.family), whose goal (press the one right button) is the same.
    TASK_FAMILY_OVERRIDES = {"Button": {"langevin_steps": 50}}
    REPORTED_KEYS = (metrics.CRITIC_LOSS, metrics.ACTOR_LOSS, metrics.ACTOR_NLL, metrics.ACTOR_KL,
                     metrics.Q_REWARD_MEAN, metrics.Q_COST_MEAN, metrics.TARGET_REWARD_MEAN,
                     metrics.TARGET_COST_MEAN, metrics.NU_MAX, *metrics.CHAIN_HEALTH_KEYS)
    ALGORITHM_CLASS = "lac_rllib.algorithms.lac.algorithm.LAC"
    RL_MODULE_CLASS = "lac_rllib.algorithms.lac.module.LACTorchRLModule"
    LEARNER_CLASS = "lac_rllib.algorithms.lac.learner.LACTorchLearner"
    MINIBATCH_FIELD = "lac_minibatch_size"

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
        # RLlib fields with LAC's values.
        self.gamma = 0.99  # [P]
        self.clip_actions = True  # the env clips; the actor is unsquashed [C]
        self.normalize_actions = False

    def resolved(self) -> dict[str, Any]:
        """``langevin_dtype`` as the chain runs it here: "auto" is bfloat16 on a CPU with native bf16
        matmuls, else float32 (lac_rllib.constrained.precision.resolve_dtype)."""
        return {"langevin_dtype": resolve_dtype(self.langevin_dtype)}

    # ----- RLlib hooks -----
    @override(AlgorithmConfig)
    def validate(self) -> None:
        super().validate()
        if self.lr_schedule == "linear" and self.lr_decay_horizon is None and self.total_env_steps is None:
            raise ValueError(
                "LAC config field total_env_steps=None is invalid with lr_schedule='linear' and no "
                "lr_decay_horizon (the decay needs a horizon); accepted: an integer >= 1, an "
                "lr_decay_horizon, or lr_schedule='constant'")

    def lr_or_schedule(self, lr: float):
        """``lr`` as RLlib's ``lr_or_lr_schedule``: piecewise-linear [[0, lr], [horizon, f·lr]] in
        env steps (RLlib's Scheduler holds the last value after the horizon), or the constant."""
        if self.lr_schedule == "constant":
            return lr
        return [[0, lr], [self.lr_horizon, lr * self.lr_final_fraction]]

    @property
    def lr_horizon(self) -> int:
        """The env steps the linear decay runs over: lr_decay_horizon, else the run's budget."""
        return int(self.lr_decay_horizon if self.lr_decay_horizon is not None else self.total_env_steps)

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict:
        """What iteration.py times LAC with: no random phase and no actor delay, so that every timed
        iteration is a training one."""
        return {"random_iterations": 0, "actor_update_start_iteration": 0} if benchmark == "iteration" else {}

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """Update seconds per env step on one CPU beyond sampling (the plan's estimate): the chain's
        share, which grows with T."""
        return CHAIN_S_PER_STEP.get(preset, 0.0) * params["langevin_steps"]

    @classmethod
    def multiplier_warmup(cls, params: dict) -> int:
        """The random iterations and those before the first actor update, then one iteration: before
        it ν's steps cannot reach the actor's actions (early stopping waits for them)."""
        start = max(int(params["random_iterations"]), int(params["actor_update_start_iteration"]))
        return (start + 1) * int(params["env_steps_per_iteration"])

    @property
    @override(AlgorithmConfig)
    def _model_config_auto_includes(self) -> dict[str, Any]:
        # The module needs the network sizes and the chain's settings (it runs the chain).
        return {**super()._model_config_auto_includes, **self.params()}
