"""Named search spaces and budgets, declared in one place and validated.

A space expands to a list of :class:`TrialSpec` (grid spaces) or, for ``search``, to a Tune
search space that Optuna samples. Each trial is one LAC run: a task, a seed and LAC overrides.
"""

from __future__ import annotations

import dataclasses
from typing import Any

PAPER_TASKS = (
    "SafetyPointGoal1-v0", "SafetyCarGoal1-v0", "SafetyPointButton1-v0", "SafetyCarButton1-v0",
    "focops/AntVelocity-v0", "focops/SwimmerVelocity-v0", "focops/HumanoidVelocity-v0",
    "focops/HumanoidCircle-v0",
)
SPACES = ("ablation", "search", "paper", "smoke")
DEFAULT_TASK = "SafetyPointGoal1-v0"  # the paper's ablation task (Table 3)
SMOKE_TASK = "lac/PointHazard-v0"

# Table 3: NI × T, VT × T, PR × β (the paper's ablations, each × seeds).
ABLATION = {
    "NI": ("langevin_steps", (30, 50, 100, 200, 500), {"langevin_start": "noninformative"}),
    "VT": ("langevin_steps", (10, 20, 30, 40, 50, 100), {}),
    "PR": ("beta", (0.0, 1.0, 5.0, 10.0, 20.0), {}),
}
SMOKE = {"smoke": ("langevin_steps", (5, 10), {})}


@dataclasses.dataclass(frozen=True)
class Budget:
    """Env steps per trial, and the LAC overrides that make that budget meaningful."""

    timesteps: int
    overrides: dict
    doc: str


BUDGETS: dict[str, Budget] = {
    "smoke": Budget(2_000, {"env_steps_per_iteration": 500, "replay_capacity": 2_000, "random_iterations": 1,
                            "actor_hidden": (32, 32), "critic_hidden": (32, 32), "num_envs_per_env_runner": 1,
                            "langevin_fused": False},
                    "seconds per trial: proves the machinery, learns nothing"),
    # 64-wide networks: with the paper's 256-wide critics one T = 500 chain costs ~8 s per
    # gradient step here (benchmarks/langevin.py), which no 30-minute ablation can afford.
    # At 10k steps the default ablation took 18.4 min here; 16k (~1.8x the sampling and gradient
    # steps) aims at the middle of the 30-45 min the sweep issue asks for.
    # One env and the eager chain: 2k-step iterations of 1000-step episodes need a single env to
    # complete episodes every iteration (10 envs would finish none for 5 iterations), and a
    # trial this short cannot repay a compile (~15-40 s per process).
    "quick": Budget(16_000, {"env_steps_per_iteration": 2_000, "replay_capacity": 10_000, "random_iterations": 1,
                             "gradient_passes": 0.5, "actor_hidden": (64, 64), "critic_hidden": (64, 64),
                             "num_envs_per_env_runner": 1, "langevin_fused": False},
                    "sized so the default ablation (48 trials) takes ~30-45 min on 2 cores"),
    "paper": Budget(2_500_000, {}, "the paper's 2.5M env steps with the SPEC presets"),
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

    def label(self) -> str:
        task = self.task.split("/")[-1]
        return f"{self.group}-{self.param}={self.value}-{task}-s{self.seed}" if self.param else f"{self.group}-{task}-s{self.seed}"


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


def grid(space: str, task: str | None, seeds: int) -> list[TrialSpec]:
    """The trials of a grid space (``ablation``, ``paper``, ``smoke``)."""
    task = default_task(space, task)
    if space == "paper":
        tasks = (task,) if task else PAPER_TASKS
        return [TrialSpec("paper", "", None, t, s, {}) for t in tasks for s in range(seeds)]
    groups = ABLATION if space == "ablation" else SMOKE if space == "smoke" else None
    if groups is None:
        raise ValueError(f"space {space!r} is not a grid")
    return [
        TrialSpec(group, param, value, task, seed, {**fixed, param: value})
        for group, (param, values, fixed) in groups.items()
        for value in values
        for seed in range(seeds)
    ]


def tune_search_space() -> dict:
    """The ``search`` space as Tune distributions (OptunaSearch converts them)."""
    from ray import tune

    kinds = {"int": lambda lo, hi: tune.randint(lo, hi + 1), "log": tune.loguniform, "uniform": tune.uniform}
    return {name: kinds[kind](lo, hi) for name, (kind, lo, hi) in SEARCH_RANGES.items()}
