"""SafeTaskConfig: what every constrained algorithm's config shares beside RLlib's
``AlgorithmConfig``: its own fields as config attributes, each checked as it is set; the task, its
cost convention and limit, the observation filter and the episode-cost callback (docs/spec.md
§5-6); the classes RLlib builds; and a run's validated config (every algorithm's ``build_config``).

An algorithm's params dataclass extends :class:`SafeTaskParams`; its config class mixes
:class:`SafeTaskConfig` in before RLlib's ``AlgorithmConfig`` and declares its fields, presets and
classes, keeping in its own ``__init__`` and hooks only what is its own.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig, NotProvided
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.utils.annotations import override
from ray.rllib.utils.serialization import deserialize_type
from ray.tune.registry import register_env

from lac_rllib.constrained.costs import EpisodeCostCallback
from lac_rllib.constrained.cpus import OneThreadPerEnvRunner, set_runners
from lac_rllib.constrained.fields import BOOL, FRACTION, LIMITS, NON_NEGATIVE, POSITIVE, one_of, or_none, param
from lac_rllib.constrained.lagrange import NU_FIXED_INDEX
from lac_rllib.constrained.obs_filter import FlooredMeanStdFilter
from lac_rllib.tasks import get_task
from lac_rllib.tasks.constraints import ConstraintSet, select
from lac_rllib.tasks.point_robot import ROBOT_VARIANTS
from lac_rllib.tasks.registry import ENV_BACKENDS


@dataclasses.dataclass
class SafeTaskParams:
    """The fields every constrained algorithm has: the task's cost convention and the observation filter."""

    # --- task ---
    cost_limit: float | None = param(None, accepts=or_none(NON_NEGATIVE))
    """b; None = the task's limit (docs/spec.md §6)."""
    constraints: dict | None = param(None, accepts=or_none(LIMITS))
    """A limit per constraint of the task (name → b, e.g. {hazards: 10, vases: 5}; the task's
    constraints: docs/tasks.md), each constraint's cost read apart and held under its own limit
    (its own cost critic and multiplier); None = one constraint, ``cost_limit`` on the summed cost
    ``info["cost"]``. Not with ``cost_limit``."""
    episode_cost_discount: float | None = param(None, accepts=or_none(FRACTION))
    """Discount of the per-step cost in Ĵ_C (1 = sum); None = the task's convention (docs/spec.md §6)."""

    env_backend: str = param("batched", accepts=one_of(ENV_BACKENDS))
    """How a navigation task with a batched backend (Point and Car × Goal, Button, Push, levels 0-2)
    steps its envs: "batched" (one vector env, lac_rllib/tasks/batched_navigation.py, equal to
    Safety-Gymnasium step for step) or "stock" (gymnasium's SyncVectorEnv of stock envs). Every
    other task runs stock whatever this says. Named in the env fingerprint."""
    robot_variant: str = param("safety_gymnasium", accepts=one_of(ROBOT_VARIANTS))
    """The Point tasks' robot: Safety-Gymnasium's (its turn a velocity servo) or "safety_gym", the
    paper's Safety-Gym Point (its turn a torque motor; lac_rllib/tasks/point_robot.py), the rest of
    the task unchanged. Other robots have one. Named in the env fingerprint of a Point task."""

    # --- observation filter ---
    obs_normalization: bool = param(True, accepts=BOOL)
    """Running mean/std observation filter [C]; its state is checkpointed."""
    obs_clip: float = param(5.0, accepts=POSITIVE)
    """Clip of the normalised observation [C]."""
    obs_std_floor: float = param(1e-2, accepts=NON_NEGATIVE)
    """The filter divides by max(std, obs_std_floor) [C], so a near-constant observation
    dimension is not blown up to ±obs_clip; 0 = RLlib's std + 1e-8."""


def make_task_env(env_config, spec):
    return spec.make(env_config)


def register_task_env(spec) -> None:
    """Make the task resolvable by RLlib env runners in every Ray process: its spec travels with
    the env creator, so a user's env (lac_rllib/tasks/user.py) needs no registry there."""
    register_env(spec.id, functools.partial(make_task_env, spec=spec))


#: An algorithm with a field of this name gets the run's budget in env steps there (``build``'s
#: ``timesteps``); without one, the budget changes nothing in its config.
BUDGET_FIELD = "total_env_steps"
#: An algorithm with a field of this name records there the preset applied, and takes
#: ``training(preset=NAME)`` and a ``preset`` in ``build``'s ``sets``.
PRESET_FIELD = "preset"


class SafeTaskConfig:
    """Mixed into an ``AlgorithmConfig`` subclass (before it): the algorithm's fields (``PARAMS``)
    as config attributes, ``.task(id)``, the derived cost limit and discount, the observation
    filter, the episode-cost callback and RLlib's hooks naming the algorithm's classes.

    Everything an algorithm declares is an attribute of its config class, inherited as Python
    inherits: ``ALGO``, ``PARAMS``, ``FIELDS``, ``PRESETS`` (preset name → field values; a task
    names its preset), its three classes, and below what the CLI, the sweep's plan and budgets,
    lac-eval and the benchmarks read (lac_rllib/algorithms/registry.py maps names to these
    classes). RLlib's own settings are set in ``__init__``."""

    #: The algorithm's name in runs, sweeps and checkpoints: the registry's name of a package
    #: algorithm; a user's config class that names none is named by its module's import path
    #: (``__init_subclass__``), the path every process imports it by.
    ALGO: str = ""
    #: What ``lac-eval --actions`` accepts for its policies (lac_rllib/evaluation.py ACTION_MODES).
    ACTIONS: tuple[str, ...] = ("generator",)
    #: The algorithm's name in OmniSafe 0.5.0, where OmniSafe implements it ("" otherwise): the peer
    #: benchmarks/peers.py times it against.
    OMNISAFE_NAME: str = ""
    #: Fields that set how fast a run goes, not what it learns: a resumed run may change them.
    SPEED_FIELDS: frozenset = frozenset()
    #: The fields a search tunes by default (``search: default``, a tuned comparison's ``tune:``):
    #: field → its range, scale and source (lac_rllib/constrained/search_space.py).
    SEARCH_SPACE: dict = {}
    #: The fields population-based training may change mid-run (sweeps/pbt.py), each with its range
    #: (lac_rllib/constrained/search_space.py): an exploit rebuilds the member with the new values
    #: and restores the donor's state into it, so a field qualifies when nothing in that state fixes
    #: it (an optimizer's state carries the donor's lr: lac_rllib/constrained/changeable.py sets it
    #: again). None: the fields of ``SEARCH_SPACE``.
    CHANGEABLE: dict | None = None
    #: The fields a sweep's named budget sets (sweeps/spaces.py BUDGETS): budget → task preset (or
    #: ``"*"``: any other) → field values; none: the preset's own values.
    BUDGET_FIELDS: dict[str, dict[str, dict[str, Any]]] = {}

    #: Preset name → the field values it sets (docs/spec.md §5).
    PRESETS: dict[str, dict[str, Any]] = {}
    #: The algorithm's params dataclass (a SafeTaskParams) and its FieldSet.
    PARAMS: type = SafeTaskParams
    FIELDS = None
    #: Task family (``TaskSpec.family``, e.g. ``Button``) → the fields this algorithm sets there,
    #: on top of the preset (LAC's T = 50 on the Button tasks).
    TASK_FAMILY_OVERRIDES: dict[str, dict[str, Any]] = {}
    #: Whether it trains on several constraints at once (``constraints`` with two or more limits):
    #: a cost critic, advantage and multiplier per constraint. One constraint runs everywhere.
    SEVERAL_CONSTRAINTS: bool = False
    #: The learner's values an iteration's row reports (lac_rllib/constrained/metrics.py names them).
    REPORTED_KEYS: tuple[str, ...] = ()
    #: The classes RLlib builds from this config, as class paths (RLlib's own form of a class in a
    #: config), imported when first asked for: the algorithm's module imports its config, and the
    #: config's module stays as light as the CLI and every env runner that unpickles it need.
    ALGORITHM_CLASS = RL_MODULE_CLASS = LEARNER_CLASS = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "ALGO" not in vars(cls):  # a user's config: named by where it lives
            cls.ALGO = cls.__module__

    @classmethod
    def changeable_space(cls) -> dict:
        """The fields PBT may change mid-run with their ranges (``CHANGEABLE``)."""
        return dict(cls.SEARCH_SPACE if cls.CHANGEABLE is None else cls.CHANGEABLE)

    @classmethod
    def changeable_fields(cls) -> tuple[str, ...]:
        return tuple(cls.changeable_space())

    @classmethod
    def benchmark_fields(cls, benchmark: str, steps: int) -> dict[str, Any]:
        """The fields benchmarks/update_step.py and iteration.py (``benchmark``) build it with to time
        ``steps`` env steps; none here."""
        return {}

    @classmethod
    def plan_update_s(cls, params: dict, preset: str) -> float:
        """The plan's estimate of its update seconds per env step on one CPU beyond sampling, for a
        trial's ``params`` on a task of ``preset``; 0 here (the estimate is the sampling alone)."""
        return 0.0

    @classmethod
    def multiplier_warmup(cls, params: dict) -> int:
        """The env steps before its multiplier can act on the policy, for a trial's ``params``
        (early stopping waits for them: sweeps/scheduler.py); 0 here."""
        return 0

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or deserialize_type(self.ALGORITHM_CLASS, error=True))
        self.task_id: str | None = None
        self._task_spec = None  # the TaskSpec itself: copies of the config (env runners) carry it
        self.num_env_runners = 0  # sample in the driver unless asked
        # Wait for the runners: an iteration needs all its env steps, and RLlib's 60 s default
        # silently drops a runner that needs longer (20k/K navigation steps at ~700 steps/s
        # already do), leaving the iteration short of data. A dead runner is found by RLlib's
        # fault tolerance, not by this timeout.
        self.sample_timeout_s = None
        self.callbacks_class = [EpisodeCostCallback, OneThreadPerEnvRunner]
        # RLlib's per-tensor NaN/inf tests off: our learners make the same guard in one test per
        # gradient step (constrained/gradients.py: 9% of a SAC-Lag step was those tests).
        self.torch_skip_nan_gradients = True
        for f in dataclasses.fields(self.PARAMS):
            setattr(self, f.name, f.default)

    @classmethod
    def build(cls, task: str, seed: int, sets: dict, num_env_runners: int = 0, timesteps: int | None = None,
              cpus: int = 1):
        """The config of a run of ``timesteps`` env steps on ``task`` (validated; no Ray needed): the
        task's preset (or ``sets["preset"]``, where the algorithm has that field), then ``sets``. The
        budget goes to the ``total_env_steps`` field unless ``sets`` names it (the horizon of a
        learning-rate decay that names no other); ``cpus`` > 1 runs the same algorithm on that many
        CPUs (:func:`~lac_rllib.constrained.cpus.use_cpus`)."""
        sets = dict(sets)
        if timesteps is not None and BUDGET_FIELD in cls.FIELDS.names:
            sets = {BUDGET_FIELD: int(timesteps), **sets}
        preset = sets.pop(PRESET_FIELD, None) if PRESET_FIELD in cls.FIELDS.names else None
        config = cls().task(task, preset=preset).training(**sets).debugging(seed=seed)
        set_runners(config, num_env_runners, cpus)
        config.validate()
        return config

    def task(self, task_id: str, *, preset: str | None = None):
        """Train on a registered safe task: its preset (or ``preset``), then this algorithm's
        overrides for the task's family, then the env. Explicit ``training(...)`` values set
        afterwards win over both."""
        spec = get_task(task_id)  # unknown id -> ValueError listing the known ones
        name = preset or spec.preset
        values = self.preset_values(name)
        self.task_id, self._task_spec = task_id, spec
        self.training(**{**values, **self.TASK_FAMILY_OVERRIDES.get(spec.family, {})})
        register_task_env(spec)
        self.environment(env=task_id)
        if PRESET_FIELD in self.FIELDS.names:
            setattr(self, PRESET_FIELD, name)
        self._apply_env_backend()
        return self

    def _apply_env_backend(self) -> None:
        """The env fields into the env's config, where the task has them: RLlib's door for a vector
        env (with the batched backend the env runners build the env through gymnasium's vector
        entry point, the task's factory given ``num_envs``; else gymnasium's SyncVectorEnv of
        single envs, RLlib's default) and a Point task's robot."""
        spec = self.task_spec
        batched = bool(spec is not None and spec.batched and self.env_backend == "batched")
        self.gym_env_vectorize_mode = "vector_entry_point" if batched else "sync"
        config = dict(self.env_config or {})
        if spec is not None and spec.batched:
            config["env_backend"] = self.env_backend
        if spec is not None and spec.robot == "Point":
            config["robot_variant"] = self.robot_variant
        elif self.robot_variant != "safety_gymnasium":
            raise ValueError(f"robot_variant={self.robot_variant!r} on {self.task_id}: only the Point tasks have "
                             "another robot; accepted here: safety_gymnasium")
        self.env_config = config

    def preset_values(self, name: str) -> dict[str, Any]:
        """The field values of the preset ``name`` (an unknown one raises a ValueError listing them)."""
        if name not in self.PRESETS:
            raise ValueError(f"unknown preset {name!r}; accepted: {', '.join(self.PRESETS)}")
        return self.PRESETS[name]

    @override(AlgorithmConfig)
    def training(self, **kwargs):
        """RLlib's settings and the algorithm's fields, each field checked as it is set (a list for a
        field declared as a tuple, as YAML and JSON write one, kept as a tuple). ``preset=NAME``,
        where the algorithm has that field, applies the preset first (the other values of the same
        call win; None leaves the values as they are)."""
        preset = kwargs.pop(PRESET_FIELD, None) if PRESET_FIELD in self.FIELDS.names else None
        if preset is not None and preset is not NotProvided:
            kwargs = {**self.preset_values(preset), **kwargs}
            setattr(self, PRESET_FIELD, preset)
        own = {k: kwargs.pop(k) for k in list(kwargs) if k in self.FIELDS.names}
        super().training(**kwargs)
        for name, value in own.items():
            if value is NotProvided:
                continue
            if isinstance(value, list) and isinstance(self.FIELDS.defaults[name], tuple):
                value = tuple(value)
            self.FIELDS.check(name, value)
            setattr(self, name, value)
        if ("env_backend" in own or "robot_variant" in own) and self.task_id:
            self._apply_env_backend()
        return self

    @override(AlgorithmConfig)
    def validate(self) -> None:
        """RLlib's checks, then every field's, then that a cost limit is set (the task's or cost_limit),
        or the constraints' limits (names the task declares; several only where the algorithm trains
        on several)."""
        super().validate()
        for name, value in self.params().items():
            self.FIELDS.check(name, value)
        if self.constraints is not None and self.cost_limit is not None:
            raise ValueError(f"cost_limit={self.cost_limit} and constraints={self.constraints} together; accepted: "
                             "one of them (cost_limit: one limit on the summed cost; constraints: a limit each)")
        several = self.constraint_set
        held = getattr(self, "nu_fixed_constraint", None)
        if held is not None and (several is None or len(several) < 2 or held not in several.names
                                 or self.nu_fixed is None):
            accepted = (f"one of {', '.join(several.names)} with nu_fixed set" if several is not None
                        and len(several) > 1 else "None (it names one of several constraints)")
            raise ValueError(f"nu_fixed_constraint={held!r} with nu_fixed={self.nu_fixed} and constraints="
                             f"{self.constraints}; accepted: {accepted}")
        if self.several_constraints is not None and not self.SEVERAL_CONSTRAINTS:
            raise ValueError(f"constraints {', '.join(several.names)}: {self.ALGO} trains on one constraint only "
                             "so far; accepted: one constraint (cost_limit, or constraints with one limit), or an "
                             "algorithm that trains on several (docs/constraints.md)")
        self.effective_cost_limit  # raises if neither cost_limit nor a task sets b

    def params(self) -> dict[str, Any]:
        """The algorithm's own fields (``PARAMS``) as a plain dict: run metadata, config.json, MLflow params."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self.PARAMS)}

    def resolved(self) -> dict[str, Any]:
        """What fields whose value is a rule ("auto") resolve to on this machine (none here; LAC's
        ``langevin_dtype``): recorded beside the params (config.json, checkpoint metadata, an MLflow
        tag) so a run says what it ran, and a resume on a machine resolving otherwise is refused."""
        return {}

    @property
    def task_spec(self):
        if self.task_id and getattr(self, "_task_spec", None) is None:
            self._task_spec = get_task(self.task_id)
        return self._task_spec if self.task_id else None

    @property
    def constraint_set(self) -> ConstraintSet | None:
        """The run's constraints and limits (``constraints``, in the task's order); None: one
        constraint on the summed cost ``info["cost"]``, at ``effective_cost_limit``. A name the task
        does not declare, or a bad limit, is a ValueError naming it and the accepted ones."""
        if self.constraints is None:
            return None
        spec = self.task_spec
        if spec is None:
            raise ValueError("constraints set and no task is set: call .task(id) first")
        return select(spec.constraints, self.constraints, task_id=spec.id)

    @property
    def several_constraints(self) -> ConstraintSet | None:
        """:attr:`constraint_set` where it holds two or more constraints apart (a cost critic and a
        multiplier each), else None: a run on one cost, however it is read."""
        several = self.constraint_set
        return several if several is not None and len(several) > 1 else None

    def constraints_data(self) -> dict | None:
        """:attr:`constraint_set` as plain data (a connector's constructor argument), or None."""
        several = self.constraint_set
        return None if several is None else several.as_data()

    def nu_fixed_model_config(self) -> dict:
        """What a module needs of ``nu_fixed_constraint``: the index of the ν_k it holds, or nothing."""
        held = getattr(self, "nu_fixed_constraint", None)
        if held is None or self.constraint_set is None:
            return {}
        return {NU_FIXED_INDEX: self.constraint_set.names.index(held)}

    @property
    def num_constraints(self) -> int:
        """K: the constraints a run holds under their limits apart (1 on the summed cost)."""
        return 1 if self.constraints is None else len(self.constraint_set)

    @property
    def effective_cost_limit(self) -> float:
        """b: ``cost_limit`` if set, else the one constraint's limit (``constraints`` with one), else
        the task's limit. With several constraints, their sum (the limit their summed cost would
        have; each constraint is held under its own: ``constraint_set``)."""
        if self.constraints is not None:
            return float(sum(self.constraint_set.limits))
        if self.cost_limit is not None:
            return float(self.cost_limit)
        if self.task_spec is None:
            raise ValueError("cost_limit is unset and no task is set: call .task(id) or set it")
        return float(self.task_spec.cost_limit)

    @property
    def effective_episode_cost_discount(self) -> float:
        """γ_C of Ĵ_C: ``episode_cost_discount`` if set, else the task's convention (1 without a task)."""
        if self.episode_cost_discount is not None:
            return float(self.episode_cost_discount)
        return float(self.task_spec.episode_cost_discount) if self.task_spec else 1.0

    def build_env_to_module_connector(self, env=None, spaces=None, device=None):
        pipeline = super().build_env_to_module_connector(env=env, spaces=spaces, device=device)
        if self.obs_normalization:
            # Running mean/std, clipped [C]. It writes the normalised observation back into
            # the episode, so replay and learner see what the actor saw; its state is part of
            # the env runners' state, hence of every checkpoint.
            pipeline.prepend(FlooredMeanStdFilter(clip_by_value=self.obs_clip, std_floor=self.obs_std_floor))
        return pipeline

    @override(AlgorithmConfig)
    def get_default_rl_module_spec(self) -> RLModuleSpec:
        return RLModuleSpec(module_class=deserialize_type(self.RL_MODULE_CLASS, error=True))

    @override(AlgorithmConfig)
    def get_default_learner_class(self):
        return deserialize_type(self.LEARNER_CLASS, error=True)
