"""The task registry: every safe task lac-rllib trains on, declared once.

A task bundles what LAC needs to know beyond the gymnasium id: where the per-step cost
comes from, how episode costs are aggregated for the Lagrange update (eq. 14), the cost
limit b, the LAC preset (docs/spec.md §5, Tables 4-5) and the observation/action sizes.

Every env we build returns the cost of a step in ``info["cost"]`` (wrappers make it so),
because that is the one place RLlib's env runners carry per-step side data into episodes.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any, Callable

import gymnasium as gym

from lac_rllib.tasks.constraints import Constraint, as_constraints

#: Preset names understood by ``LACConfig.preset`` (docs/spec.md §5 columns).
MUJOCO, SAFETY_GYM, TINY = "mujoco", "safety_gym", "tiny"
#: How a task with a batched backend steps its envs (the ``env_backend`` field of every algorithm).
ENV_BACKENDS = ("batched", "stock")


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """Everything lac-rllib knows about one safe task."""

    #: Gymnasium id (with namespace), e.g. ``"lac/PointHazard-v0"``.
    id: str
    #: ``"module:function"`` building the env from an env-config dict. A string (not a
    #: callable) so remote env runners import it themselves: that import is what pulls
    #: in compatibility patches in every process.
    factory: str
    #: Cost limit b on the episode cost.
    cost_limit: float
    #: Discount γ_C used to aggregate the per-step cost into the episode cost Ĵ_C for
    #: the ν update and the reported ``episode_cost``: 1.0 means a plain sum (Safety-Gym
    #: convention), 0.99 the FOCOPS discounted convention.
    episode_cost_discount: float
    #: Which LAC preset applies (``"mujoco"``, ``"safety_gym"`` or ``"tiny"``).
    preset: str
    #: Observation and action sizes (flat Box spaces).
    obs_dim: int
    act_dim: int
    #: Human-readable source of the per-step cost, for docs and run metadata.
    cost_source: str = 'info["cost"]'
    #: Keyword arguments passed to the factory by default.
    kwargs: dict = dataclasses.field(default_factory=dict)
    #: The task's family (Safety-Gymnasium's task without its level: ``Goal``, ``Button``, ...; empty
    #: for others): an algorithm may set fields per family (``TASK_FAMILY_OVERRIDES``).
    family: str = ""
    #: One env step's time over one of its preset's reference task (Safety-Gymnasium's navigation
    #: tasks: ``SafetyPointGoal1-v0``), raw steps with random actions as ``benchmarks/envs.py
    #: --step-costs`` measures them: the sweep plan scales the env's share of a trial by it (a
    #: Button1 step costs ~3 Goal1 steps, docs/sweeps.md). 1.0 where not measured. A measurement,
    #: not part of what the task is: left out of a spec's equality.
    step_cost: float = dataclasses.field(default=1.0, compare=False)
    #: The env's episode limit, steps before it truncates (an episode may end sooner): the sweep
    #: plan counts each evaluation episode at it. 1,000 (Safety-Gymnasium's and the velocity
    #: tasks') where a task does not say; Circle and Run are 500. A planning figure, left out of a
    #: spec's equality as ``step_cost`` is.
    episode_steps: int = dataclasses.field(default=1000, compare=False)
    #: Whether its factory also builds a batched vector env (given ``num_envs``, with
    #: ``env_backend: batched``): lac_rllib/tasks/batched_navigation.py. A way to step the same env,
    #: not part of what the task is: left out of a spec's equality (the fingerprint names the backend).
    batched: bool = dataclasses.field(default=False, compare=False)
    #: A navigation task's robot (``Point``, ``Car``, ...; empty for others): a Point task also runs
    #: Safety-Gym's Point (``robot_variant``, lac_rllib/tasks/point_robot.py).
    robot: str = dataclasses.field(default="", compare=False)
    #: The parts of its safety specification, each a name and the ``info`` keys of its cost
    #: (lac_rllib/tasks/constraints.py): what ``constraints: {NAME: limit}`` may name. Empty: the
    #: task has only ``info["cost"]``.
    constraints: tuple[Constraint, ...] = ()

    def __post_init__(self):
        # A spec that travelled as plain data (a user task's definition) carries them as dicts.
        object.__setattr__(self, "constraints", as_constraints(self.constraints))

    def make(self, env_config: dict | None = None) -> gym.Env:
        """Build one env instance (works in any process)."""
        module, func = self.factory.split(":")
        fn: Callable[..., gym.Env] = getattr(importlib.import_module(module), func)
        cfg = {**self.kwargs, **(dict(env_config) if env_config else {})}
        return fn(cfg)


_TASKS: dict[str, TaskSpec] = {}


def register(spec: TaskSpec) -> TaskSpec:
    """Add ``spec`` to the registry and to gymnasium's (so ``gym.make(id)`` works too)."""
    _TASKS[spec.id] = spec
    if spec.id not in gym.registry:
        gym.register(id=spec.id, entry_point=_gym_entry_point, kwargs={"task_id": spec.id})
    return spec


def _gym_entry_point(task_id: str, **env_config: Any) -> gym.Env:
    return get_task(task_id).make(env_config)


def known_tasks() -> list[str]:
    _load_builtin()
    return sorted(_TASKS)


def get_task(task_id: str) -> TaskSpec:
    """Look a task up; an unknown id raises ``ValueError`` naming the closest known ones (a few:
    the full list is docs/tasks.md, ``known_tasks()``)."""
    _load_builtin()
    try:
        return _TASKS[task_id]
    except (KeyError, TypeError):
        import difflib

        from lac_rllib.errors import excerpt

        close = difflib.get_close_matches(str(task_id), sorted(_TASKS), n=3, cutoff=0.0)
        raise ValueError(f"unknown task {excerpt(task_id)}; closest known tasks: {', '.join(close)} "
                         f"(all {len(_TASKS)}: docs/tasks.md)") from None


def _load_builtin() -> None:
    # Importing the package registers the built-in tasks (cheap: no MuJoCo import).
    importlib.import_module("lac_rllib.tasks")
