"""The safe-task part of every constrained algorithm's config: which task, its cost convention and
limit, the observation filter, the episode-cost callback (docs/spec.md §5-6).

An algorithm's params dataclass extends :class:`SafeTaskParams`; its config class mixes
:class:`SafeTaskConfig` in before RLlib's ``AlgorithmConfig`` and declares its ``PRESETS``.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

from ray.tune.registry import register_env

from lac_rllib.constrained.costs import EpisodeCostCallback
from lac_rllib.constrained.cpus import OneThreadPerEnvRunner
from lac_rllib.constrained.fields import BOOL, FRACTION, NON_NEGATIVE, POSITIVE, or_none, param
from lac_rllib.constrained.obs_filter import FlooredMeanStdFilter
from lac_rllib.tasks import get_task


@dataclasses.dataclass
class SafeTaskParams:
    """The fields every constrained algorithm has: the task's cost convention and the observation filter."""

    # --- task ---
    cost_limit: float | None = param(None, accepts=or_none(NON_NEGATIVE))
    """b; None = the task's limit (docs/spec.md §6)."""
    episode_cost_discount: float | None = param(None, accepts=or_none(FRACTION))
    """Discount of the per-step cost in Ĵ_C (1 = sum); None = the task's convention (docs/spec.md §6)."""

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


class SafeTaskConfig:
    """Mixed into an ``AlgorithmConfig`` subclass (before it): ``.task(id)``, the derived cost
    limit and discount, the observation filter and the episode-cost callback.

    The subclass declares ``PRESETS`` (preset name → field values; a task names its preset) and
    sets its params' defaults in ``__init__``."""

    #: Preset name → the field values it sets (docs/spec.md §5).
    PRESETS: dict[str, dict[str, Any]] = {}
    #: The algorithm's params dataclass (a SafeTaskParams) and its FieldSet.
    PARAMS: type = SafeTaskParams
    FIELDS = None
    #: Task family (``TaskSpec.family``, e.g. ``Button``) → the fields this algorithm sets there,
    #: on top of the preset (LAC's T = 50 on the Button tasks).
    TASK_FAMILY_OVERRIDES: dict[str, dict[str, Any]] = {}
    #: The learner's values an iteration's row reports (lac_rllib/constrained/metrics.py names them).
    REPORTED_KEYS: tuple[str, ...] = ()

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
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

    def task(self, task_id: str, *, preset: str | None = None):
        """Train on a registered safe task: its preset (or ``preset``), then this algorithm's
        overrides for the task's family, then the env. Explicit ``training(...)`` values set
        afterwards win over both."""
        spec = get_task(task_id)  # unknown id -> ValueError listing the known ones
        name = preset or spec.preset
        if name not in self.PRESETS:
            raise ValueError(f"unknown preset {name!r}; accepted: {', '.join(self.PRESETS)}")
        self.task_id, self._task_spec = task_id, spec
        self.training(**{**self.PRESETS[name], **self.TASK_FAMILY_OVERRIDES.get(spec.family, {})})
        register_task_env(spec)
        self.environment(env=task_id)
        return self

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
    def effective_cost_limit(self) -> float:
        """b: ``cost_limit`` if set, else the task's limit."""
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
