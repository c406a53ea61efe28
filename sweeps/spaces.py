"""Named search spaces and budgets, declared in one place and validated.

A space expands to a list of :class:`TrialSpec` (grid spaces) or, for ``search``, to a Tune
search space that Optuna samples. Each trial is one run of one algorithm (``algo``: LAC or a
baseline, lac_rllib/algorithms/registry.py): a task, a seed and the algorithm's field overrides.
"""

from __future__ import annotations

import dataclasses
from typing import Any

PAPER_TASKS = (
    "SafetyPointGoal1-v0", "SafetyCarGoal1-v0", "SafetyPointButton1-v0", "SafetyCarButton1-v0",
    "focops/AntVelocity-v0", "focops/SwimmerVelocity-v0", "focops/HumanoidVelocity-v0",
    "focops/HumanoidCircle-v0",
)
SPACES = ("ablation", "search", "paper", "smoke", "compare")
REPEAT_INDEX = "__trial_index__"  # ray.tune.search.repeater.TRIAL_INDEX (not imported: no Ray before the plan)
DEFAULT_TASK = "lac/PointHazard-v0"  # the default ablation: a task that learns in minutes
PAPER_ABLATION_TASK = "SafetyPointGoal1-v0"  # the paper's Table 3 (--task ... --budget paper)
QUICK_TINY_STEPS = 40_000
SMOKE_TASK = "lac/PointHazard-v0"
#: The compare space: every algorithm at one budget (LAC first: the others are compared with it).
COMPARE_ALGOS = ("lac", "ppo_lag", "sac_lag")

# Table 3: NI × T, VT × T, PR × β (the paper's ablations, each × seeds).
ABLATION = {
    "NI": ("langevin_steps", (30, 50, 100, 200, 500), {"langevin_start": "noninformative"}),
    "VT": ("langevin_steps", (10, 20, 30, 40, 50, 100), {}),
    "PR": ("beta", (0.0, 1.0, 5.0, 10.0, 20.0), {}),
}
SMOKE = {"smoke": ("langevin_steps", (5, 10), {})}
# The default ablation's grid (the quick budget on lac/PointHazard-v0): Table 3's three groups at
# the chain lengths the tiny task's preset (T = 10) is built around. The paper's T up to 500 would
# cost ~50x a T = 10 trial's chain: 48 trials do not fit the 35 minutes on 2 cores that a first
# run gets; --task SafetyPointGoal1-v0 --budget paper runs Table 3 itself.
QUICK_ABLATION = {
    "NI": ("langevin_steps", (20, 30), {"langevin_start": "noninformative"}),
    "VT": ("langevin_steps", (10, 20, 30), {}),
    "PR": ("beta", (0.5, 1.0), {}),
}


@dataclasses.dataclass(frozen=True)
class Budget:
    """Env steps per trial and the LAC overrides that make that budget meaningful, per task preset
    (``lac_rllib.algorithms.lac.config.PRESETS``; ``"*"`` for any other preset). Every algorithm
    gets the same env steps; a baseline gets its own overrides (``by_algo``: algo → preset → fields)."""

    by_preset: dict
    doc: str
    #: The ablation's groups at this budget, per preset, where they differ from Table 3's ``ABLATION``.
    ablation_by_preset: dict = dataclasses.field(default_factory=dict)
    #: A baseline's overrides at this budget, per preset ("*": any other); none: its preset's values.
    by_algo: dict = dataclasses.field(default_factory=dict)

    def for_preset(self, preset: str, algo: str = "lac") -> tuple[int, dict]:
        steps, lac_overrides = self.by_preset.get(preset, self.by_preset["*"])
        if algo == "lac":
            return steps, lac_overrides
        own = self.by_algo.get(algo, {})
        return steps, own.get(preset, own.get("*", {}))

    def for_task(self, task: str, algo: str = "lac") -> tuple[int, dict]:
        from lac_rllib.tasks import get_task

        return self.for_preset(get_task(task).preset, algo)

    def describe(self) -> str:
        steps = ", ".join(f"{n:,}" + ("" if p == "*" else f" on {p} tasks") for p, (n, _) in self.by_preset.items())
        return f"{steps} env steps: {self.doc}"


# A trial this short cannot repay a compile of the fused chain (~15-40 s per process): eager.
_SMOKE = {"env_steps_per_iteration": 500, "replay_capacity": 2_000, "random_iterations": 1,
          "actor_hidden": (32, 32), "critic_hidden": (32, 32), "num_envs_per_env_runner": 1, "langevin_fused": False}
# The baselines at the smoke budget (same sizes) and at the quick budget on the paper's tasks (64-wide
# nets, one env, 2k-step iterations as LAC's); on the tiny task their own tiny presets are the quick budget.
_SMOKE_BY_ALGO = {
    "ppo_lag": {"*": {"train_batch_size_per_learner": 500, "minibatch_size": 100, "num_epochs": 2, "hidden": (32, 32),
                      "num_envs_per_env_runner": 1}},
    "sac_lag": {"*": {"env_steps_per_iteration": 500, "replay_capacity": 2_000, "random_env_steps": 500,
                      "warmup_env_steps": 500, "actor_hidden": (32, 32), "critic_hidden": (32, 32),
                      "num_envs_per_env_runner": 1}},
}
_QUICK_BY_ALGO = {
    "ppo_lag": {"tiny": {}, "*": {"train_batch_size_per_learner": 2_000, "hidden": (64, 64),
                                  "num_envs_per_env_runner": 1}},
    "sac_lag": {"tiny": {}, "*": {"env_steps_per_iteration": 2_000, "replay_capacity": 10_000,
                                  "random_env_steps": 2_000, "actor_hidden": (64, 64), "critic_hidden": (64, 64),
                                  "num_envs_per_env_runner": 1}},
}
BUDGETS: dict[str, Budget] = {
    "smoke": Budget({"*": (2_000, _SMOKE)}, "seconds per trial: proves the machinery, learns nothing",
                    by_algo=_SMOKE_BY_ALGO),
    # The default ablation (python sweeps/run.py --space ablation): on the tiny task, where
    # QUICK_TINY_STEPS of the tiny preset learn, on a reduced Table 3 grid (QUICK_ABLATION);
    # calibrated by running it (docs/sweeps.md). The fused chain pays here: a T = 30 trial runs
    # ~1,400 chains of 30 steps, and the compiled kernels are cached on disk across trials. Ten
    # envs per runner: RLlib's per-step machinery took 55% of a one-env trial (py-spy); ten
    # 100-step episodes still complete in every 1,000-step iteration.
    # On the paper's tasks 16k steps (64-wide nets, one env so 2k-step iterations complete
    # 1000-step episodes) are a machinery check: the paper's 2.5M cannot be shrunk that far.
    "quick": Budget({"tiny": (QUICK_TINY_STEPS, {"langevin_steps": 20, "langevin_fused": True,
                                                  "num_envs_per_env_runner": 10}),
                     "*": (16_000, {"env_steps_per_iteration": 2_000, "replay_capacity": 10_000, "random_iterations": 1,
                                    "gradient_passes": 0.5, "actor_hidden": (64, 64), "critic_hidden": (64, 64),
                                    "num_envs_per_env_runner": 1, "langevin_fused": False})},
                    "the default ablation learns lac/PointHazard-v0 in ~30 min on 2 cores; on the paper's tasks "
                    "a machinery check that learns nothing",
                    ablation_by_preset={"tiny": QUICK_ABLATION}, by_algo=_QUICK_BY_ALGO),
    "paper": Budget({"*": (2_500_000, {})}, "the paper's 2.5M env steps with the docs/spec.md §5 presets"),
}

# Optuna TPE ranges for the search space (T int, η and λ log-uniform, β uniform).
SEARCH_RANGES = {
    "langevin_steps": ("int", 10, 100),
    "langevin_step_size": ("log", 1e-5, 1e-3),
    "temperature": ("log", 1e-4, 1e-2),
    "beta": ("uniform", 0.0, 20.0),
}


@dataclasses.dataclass(frozen=True)
class TrialSpec:
    """One point of a grid: which group it belongs to and what it sets."""

    group: str
    param: str
    value: Any
    task: str
    seed: int
    overrides: dict
    #: Test hook: the trial raises at this iteration (exercises the failure path end to end).
    fail_at_iteration: int | None = None
    #: The trial runs LAC's defaults (for its task and budget): the baseline of the report's comparisons.
    default: bool = False
    #: A search trial's values as Optuna sampled them (its name); None for grid trials.
    sampled: dict | None = None
    #: ``algo`` and every field of that algorithm in this trial, as :func:`trial_params` resolves
    #: them (at plan time for a grid trial, in the trial for a search sample); what the estimate,
    #: the trainable and the default flag read. None until resolved.
    params: dict | None = None

    @property
    def algo(self) -> str:
        """The trial's algorithm (lac_rllib/algorithms/registry.py)."""
        from lac_rllib.algorithms.registry import ALGO_FIELD, DEFAULT_ALGO

        return (self.params or self.overrides).get(ALGO_FIELD, DEFAULT_ALGO)

    def config_label(self) -> str:
        """The configuration without its seed (MLflow's ``lac.config`` tag); it names a baseline."""
        if self.sampled is not None:
            return search_label(self.sampled, None)
        task = self.task.split("/")[-1]
        label = f"{self.group}-{self.param}={self.value}-{task}" if self.param else f"{self.group}-{task}"
        return label if self.algo == "lac" or self.param == "algo" else f"{self.algo}-{label}"

    def label(self) -> str:
        return f"{self.config_label()}-s{self.seed}"


def config_id(task: str, timesteps: int, params: dict) -> str:
    """A stable id of a configuration without its seed: what it learns with (task, budget, every
    LAC field except the speed-only ones). Equal across seeds, different between configurations."""
    import hashlib
    import json

    speed = speed_fields(params)
    what = {"task": task, "timesteps": int(timesteps), **{k: v for k, v in params.items() if k not in speed}}
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:12]


def speed_fields(params: dict) -> frozenset:
    """The speed-only fields of the algorithm ``params`` names (``algo``; LAC without one)."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, DEFAULT_ALGO, algo_config

    return algo_config(params.get(ALGO_FIELD, DEFAULT_ALGO)).SPEED_FIELDS


# Short names of the searched fields in a search trial's label (ASCII: labels name Tune's trials).
SEARCH_LABEL = {"langevin_steps": "T", "langevin_step_size": "eta", "temperature": "lam", "beta": "beta"}


def search_label(overrides: dict, seed: int | None) -> str:
    """A search trial's label from its sampled values, e.g. ``search-T=37-eta=2.1e-04-lam=3.0e-03-beta=4.2-s0``
    (without ``-s0`` when ``seed`` is None: the configuration)."""
    parts = []
    for name, short in SEARCH_LABEL.items():
        v = overrides.get(name)
        if v is not None:
            kind = SEARCH_RANGES[name][0]
            fmt = {"int": "d", "log": ".1e"}.get(kind, ".1f")
            parts.append(f"{short}={v:{fmt}}")
    return "-".join(["search", *parts, *([] if seed is None else [f"s{seed}"])])


def trial_spec(config: dict) -> TrialSpec:
    """A Tune trial's config as the TrialSpec it runs: a grid trial carries its own, resolved at
    plan time (``trial``); a search trial is made from what Optuna sampled (``overrides``), resolved
    here through the same :func:`trial_params` (with the sweep's ``budget`` and ``sets``), its seed
    the index among its sample's seeds (Tune's Repeater numbers the repeats of one Optuna sample 0..N-1)."""
    if "trial" in config:
        return TrialSpec(**config["trial"])
    task, budget, sets = config["task"], config["budget"], config.get("sets", {})
    sampled = dict(config["overrides"])
    params = trial_params(task, budget, sets, sampled)
    return TrialSpec("search", "", None, task, int(config.get(REPEAT_INDEX, 0)), sampled, sampled=sampled,
                     params=params, default=params == trial_params(task, budget, sets))


def validate(space: str, task: str | None, budget: str, seeds: int) -> None:
    """Raise ValueError naming the bad value and the accepted ones (no Ray needed)."""
    from lac_rllib.tasks import get_task

    if space not in SPACES:
        raise ValueError(f"unknown space {space!r}; accepted: {', '.join(SPACES)}")
    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; accepted: {', '.join(BUDGETS)}")
    if not isinstance(seeds, int) or seeds < 1:
        raise ValueError(f"--seeds {seeds!r} is invalid; accepted: an integer >= 1")
    if task is not None:
        get_task(task)  # unknown id -> ValueError listing the known ones


def default_task(space: str, task: str | None) -> str | None:
    if task is not None:
        return task
    return {"smoke": SMOKE_TASK, "paper": None}.get(space, DEFAULT_TASK)


def grid(space: str, task: str | None, seeds: int, budget: str = "paper") -> list[TrialSpec]:
    """The trials of a grid space (``ablation``, ``paper``, ``smoke``) at ``budget``."""
    from lac_rllib.tasks import get_task

    task = default_task(space, task)
    if space == "compare":  # algo × seeds: every algorithm at the same budget, LAC first
        return [TrialSpec("compare", "algo", algo, task, seed, {"algo": algo})
                for algo in COMPARE_ALGOS for seed in range(seeds)]
    if space == "paper":
        tasks = (task,) if task else PAPER_TASKS
        return [TrialSpec("paper", "", None, t, s, {}) for t in tasks for s in range(seeds)]
    ablation = BUDGETS[budget].ablation_by_preset.get(get_task(task).preset, ABLATION)
    groups = ablation if space == "ablation" else SMOKE if space == "smoke" else None
    if groups is None:
        raise ValueError(f"space {space!r} is not a grid")
    return [
        TrialSpec(group, param, value, task, seed, {**fixed, param: value})
        for group, (param, values, fixed) in groups.items()
        for value in values
        for seed in range(seeds)
    ]


def trial_params(task: str, budget: str, sets: dict, overrides: dict | None = None) -> dict[str, Any]:
    """``algo`` and every field of that algorithm in a trial of ``task`` at ``budget``: the one place
    the precedence is written. The algorithm is the trial's ``algo`` override, else ``--set algo=``,
    else LAC. Then the algorithm's preset for the task < the task's own overrides (LAC only:
    ``TaskSpec.overrides``, e.g. T = 50 on the Button tasks) < the budget's overrides for that
    algorithm < the user's ``--set`` < the trial's own ``overrides`` (the swept or sampled value).
    ``build_config`` applies the first two (``SafeTaskConfig.task``); the horizon of the
    learning-rate decay is the budget's env steps unless an override names another."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, build_config, split_algo

    algo, fields = split_algo({**sets, **(overrides or {})})
    steps, budget_overrides = BUDGETS[budget].for_task(task, algo)
    config = build_config(algo, task, 0, {**budget_overrides, **fields}, timesteps=steps)
    return {ALGO_FIELD: algo, **config.params()}


def resolve_trials(trials: list[TrialSpec], budget: str, sets: dict) -> list[TrialSpec]:
    """The grid's trials with their LAC fields resolved (:func:`trial_params`), and the default flag on
    those whose overrides change nothing: they run LAC's defaults (for their task, at this budget,
    with the user's --set), the baseline every configuration is compared with."""
    base, out = {}, []
    for t in trials:
        if t.task not in base:
            base[t.task] = trial_params(t.task, budget, sets)
        params = trial_params(t.task, budget, sets, t.overrides)
        out.append(dataclasses.replace(t, params=params, default=params == base[t.task]))
    return out


def tune_search_space() -> dict:
    """The ``search`` space as Tune distributions (OptunaSearch converts them)."""
    from ray import tune

    kinds = {"int": lambda lo, hi: tune.randint(lo, hi + 1), "log": tune.loguniform, "uniform": tune.uniform}
    return {name: kinds[kind](lo, hi) for name, (kind, lo, hi) in SEARCH_RANGES.items()}
