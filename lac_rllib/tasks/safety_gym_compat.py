"""Make ``safety_gymnasium==1.0.0`` importable and usable on our stack.

Stack: Python 3.11, gymnasium 1.2.2, numpy 2.4, mujoco 4.0. Safety-Gymnasium 1.0.0 (the newest
release, unmaintained) was written for Python <= 3.10, gymnasium 0.28.1, numpy 1.23 and
mujoco 2.3.3, and is installed with ``pip install --no-deps``. Nothing in site-packages is
edited: :func:`apply` fixes everything from here, once per process, and every env factory of
ours calls it before touching ``safety_gymnasium`` (RLlib env runners import the factory by
string, so every process that builds an env gets the fixes).

What :func:`apply` patches, and how narrowly (docs/dependencies.md, "Compatibility fixes", items 1-5;
item 6 is documented in docs/tasks.md):

1. **Renamed gymnasium wrapper modules** (``ModuleNotFoundError`` at import).
   ``safety_gymnasium`` imports ``gymnasium.wrappers.compatibility`` (``EnvCompatibility``),
   ``.autoreset`` (``AutoResetWrapper``), ``.time_limit`` (``TimeLimit``), ``.env_checker``
   (``PassiveEnvChecker``) and ``.normalize`` (``NormalizeObservation``, ``NormalizeReward``,
   ``RunningMeanStd``), which gymnasium 1.0 removed/renamed. Fix: stand-in modules mapping those
   names to gymnasium 1.x's ``Autoreset``, ``TimeLimit``, ``PassiveEnvChecker``,
   ``NormalizeObservation``, ``NormalizeReward`` and ``gymnasium.wrappers.utils.RunningMeanStd``
   (``EnvCompatibility`` has no successor: a stub that raises if ever instantiated; it is only
   used with ``apply_api_compatibility=True``, which nothing sets). The used subclasses
   (``SafeTimeLimit``, ``SafePassiveEnvChecker``) only touch attributes gymnasium 1.2.2 still has
   (``_elapsed_steps``, ``_max_episode_steps``, ``checked_step``). The safe normalize and
   autoreset wrappers become importable but are not used by lac-rllib and not vouched for.
   ``gymnasium_robotics`` (imported at top level by the multi-agent tasks only) gets a stub
   package when it is not installed; its ``MultiAgentMujocoEnv`` raises if instantiated.
   All these stand-ins live in ``sys.modules`` only *while* ``safety_gymnasium`` is imported and
   are removed afterwards, so no other code sees them (``import gymnasium.wrappers.autoreset``
   still fails elsewhere, as it should).
2. **Unhashable numpy defaults in dataclasses** (``ValueError: mutable default <class
   'numpy.ndarray'> for field color is not allowed``, Python >= 3.11). The geom/mocap/free-geom
   dataclasses in ``safety_gymnasium/assets`` use ``color: np.array = COLOR[...]``. Fix: while
   the package is imported, ``dataclasses._get_field`` is wrapped so that, *only* for classes
   whose ``__module__`` starts with ``safety_gymnasium`` and *only* for ``np.ndarray`` defaults,
   the hashability check is skipped; the field keeps the very same array object as its default
   (exactly Python 3.10's semantics, shared default included). Every module defining such
   dataclasses (``safety_gymnasium.assets.*`` via ``safety_gymnasium.builder``) is imported
   eagerly under the wrapper, and the original ``_get_field`` is restored afterwards.
3. **EnvSpec without ``apply_api_compatibility``/``autoreset``** (``AttributeError`` /
   ``TypeError`` in ``safety_gymnasium.make``). Fix: in ``safety_gymnasium.utils.registration``
   only, the name ``EnvSpec`` is rebound to :class:`SafetyEnvSpec` (a gymnasium ``EnvSpec``
   subclass with the two fields, both ``False``) and ``_find_spec`` is wrapped to return
   ``SafetyEnvSpec`` copies. gymnasium's own ``EnvSpec`` is untouched.
4. **Car robots, numpy >= 2.4**: ``MjModel.jnt(array([3]))`` is refused (mujoco 4's
   ``sensor(i).objid`` is a shape-(1,) array that numpy 2.4 no longer turns into an int).
   Fix: ``BaseAgent._init_jnt_sensors`` is wrapped so that, for the duration of that call only,
   ``self.engine.model`` is a thin proxy whose ``jnt(i)`` converts a size-1 integer array to
   ``int``; all else is delegated. ``mujoco.MjModel`` itself is not patched. (The same call in
   ``safety_gymnasium/assets/robot.py`` belongs to the ``Robot`` class, which nothing uses.)

Plus one registry fix: ``safety_gymnasium``'s ``register`` also registers its ids (e.g.
``SafetyPointGoal1-v0``) in gymnasium's registry, overwriting the lac-rllib task of the same id
(a 6-tuple env would then come out of ``gym.make``). :func:`apply` keeps safety_gymnasium's
specs in a private table (:func:`safety_spec`; the wrapped ``_find_spec`` consults it, so
``safety_gymnasium.make(id)`` and the ``...Gymnasium-v0`` ids keep working) and puts the
lac-rllib entries back in gymnasium's registry.

Gymnasium's own MuJoCo envs are not affected (tested: seeded ``Ant-v5`` trajectories are
bit-identical with and without :func:`apply`).
5. **Offscreen rendering** (``TypeError`` in ``render``): gymnasium 1.x's ``OffScreenViewer``
   requires width/height that safety-gymnasium does not pass; they default to the model's
   offscreen buffer size (videos in ``sweeps/evaluate.py --video``).
6. **Doggo and Ant robots, numpy >= 2.4** (``TypeError: only 0-dimensional arrays can be
   converted to Python scalars`` at the first ``reset``): ``BaseAgent.obs_sensor`` does
   ``float(self.get_sensor(name))`` on each hinge-angle sensor, a shape-(1,) array (Doggo and
   Ant have such sensors; Point, Car and Racecar do not and built before). Fix: the name
   ``float`` in ``safety_gymnasium.bases.base_agent``'s globals (that ``float(...)`` is the only
   call of it in the module) is bound to :func:`_scalar_float`, which takes the single element
   of a size-1 array, exactly what numpy < 2.4 did (same float64 value), and is the builtin
   otherwise. Python's builtin ``float`` is untouched everywhere else.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import importlib.util
import sys
import threading
import types
from typing import Any, Iterator

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

__all__ = ["SafetyEnvSpec", "apply", "is_applied", "safety_spec"]

_LOCK = threading.RLock()
_STATE: dict[str, Any] = {"module": None}
#: safety_gymnasium's own gymnasium EnvSpecs for ids that lac-rllib registers itself.
_SAFETY_SPECS: dict[str, EnvSpec] = {}


@dataclasses.dataclass
class SafetyEnvSpec(EnvSpec):
    """gymnasium 1.x ``EnvSpec`` plus the two gymnasium-0.28 fields safety_gymnasium reads."""

    autoreset: bool = False
    apply_api_compatibility: bool = False

    @classmethod
    def from_spec(cls, spec: EnvSpec) -> "SafetyEnvSpec":
        if isinstance(spec, cls):
            return spec
        init = {f.name: getattr(spec, f.name) for f in dataclasses.fields(EnvSpec) if f.init}
        return cls(**init)


# --------------------------------------------------------------------------- patch 1


class _EnvCompatibilityStub:
    """gymnasium 0.28's EnvCompatibility (old step API) has no gymnasium 1.x successor."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise NotImplementedError(
            "EnvCompatibility (apply_api_compatibility=True) is not available with gymnasium 1.x"
        )


class _MultiAgentMujocoEnvStub:
    """Stand-in for gymnasium_robotics' MultiAgentMujocoEnv (not installed)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise ImportError(
            "gymnasium_robotics is not installed: Safety-Gymnasium's multi-agent tasks are "
            "unavailable (lac-rllib does not use them)"
        )


def _shim_modules() -> dict[str, types.ModuleType]:
    from gymnasium.wrappers import (
        Autoreset,
        NormalizeObservation,
        NormalizeReward,
        PassiveEnvChecker,
        TimeLimit,
    )
    from gymnasium.wrappers.utils import RunningMeanStd

    def mod(name: str, **attrs: Any) -> types.ModuleType:
        m = types.ModuleType(name, f"lac_rllib safety_gym_compat stand-in for {name}")
        m.__dict__.update(attrs)
        return m

    shims = {
        m.__name__: m
        for m in (
            mod("gymnasium.wrappers.compatibility", EnvCompatibility=_EnvCompatibilityStub),
            mod("gymnasium.wrappers.autoreset", AutoResetWrapper=Autoreset),
            mod("gymnasium.wrappers.time_limit", TimeLimit=TimeLimit),
            mod("gymnasium.wrappers.env_checker", PassiveEnvChecker=PassiveEnvChecker),
            mod(
                "gymnasium.wrappers.normalize",
                NormalizeObservation=NormalizeObservation,
                NormalizeReward=NormalizeReward,
                RunningMeanStd=RunningMeanStd,
            ),
        )
    }
    if importlib.util.find_spec("gymnasium_robotics") is None:
        names = [
            "gymnasium_robotics",
            "gymnasium_robotics.envs",
            "gymnasium_robotics.envs.multiagent_mujoco",
            "gymnasium_robotics.envs.multiagent_mujoco.mujoco_multi",
        ]
        for name in names:
            shims[name] = mod(name)
            shims[name].__path__ = []  # a package, so submodule imports resolve via sys.modules
        shims[names[-1]].MultiAgentMujocoEnv = _MultiAgentMujocoEnvStub
    return shims


@contextlib.contextmanager
def _temporary_modules(mods: dict[str, types.ModuleType]) -> Iterator[None]:
    added = [name for name in mods if name not in sys.modules]
    for name in added:
        sys.modules[name] = mods[name]
    try:
        yield
    finally:
        for name in added:
            if sys.modules.get(name) is mods[name]:
                del sys.modules[name]


# --------------------------------------------------------------------------- patch 2


class _Placeholder:
    """Hashable stand-in default, swapped in only around the hashability check."""


@contextlib.contextmanager
def _lenient_ndarray_dataclass_defaults() -> Iterator[None]:
    original = dataclasses._get_field  # type: ignore[attr-defined]

    def _get_field(cls, a_name, a_type, *args, **kwargs):
        default = getattr(cls, a_name, dataclasses.MISSING)
        if not (
            isinstance(default, np.ndarray)
            and getattr(cls, "__module__", "").startswith("safety_gymnasium")
        ):
            return original(cls, a_name, a_type, *args, **kwargs)
        own = a_name in cls.__dict__
        setattr(cls, a_name, _Placeholder())
        try:
            f = original(cls, a_name, a_type, *args, **kwargs)
        finally:
            if own:
                setattr(cls, a_name, default)
            else:
                delattr(cls, a_name)
        f.default = default  # the same array object, as Python 3.10 would keep it
        return f

    dataclasses._get_field = _get_field  # type: ignore[attr-defined]
    try:
        yield
    finally:
        dataclasses._get_field = original  # type: ignore[attr-defined]


# --------------------------------------------------------------------------- patch 3


def _patch_registration() -> None:
    registration = importlib.import_module("safety_gymnasium.utils.registration")
    if getattr(registration, "_lac_rllib_patched", False):
        return
    original_find_spec = registration._find_spec

    def _find_spec(env_id: str) -> SafetyEnvSpec:
        spec = _SAFETY_SPECS.get(env_id) if isinstance(env_id, str) else None
        if spec is None:
            spec = original_find_spec(env_id)
        return SafetyEnvSpec.from_spec(spec)

    registration.EnvSpec = SafetyEnvSpec
    registration._find_spec = _find_spec
    registration._lac_rllib_patched = True


# --------------------------------------------------------------------------- patch 4


class _IntJointIdModel:
    """Delegating proxy for an ``MjModel`` whose ``jnt()`` accepts size-1 integer arrays."""

    __slots__ = ("_model",)

    def __init__(self, model: Any) -> None:
        object.__setattr__(self, "_model", model)

    def jnt(self, key: Any) -> Any:
        if isinstance(key, np.ndarray) and key.size == 1 and key.dtype.kind in "iu":
            key = int(key.reshape(-1)[0])
        return self._model.jnt(key)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._model, name)


def _patch_car_joint_ids() -> None:
    base_agent = importlib.import_module("safety_gymnasium.bases.base_agent")
    cls = base_agent.BaseAgent
    original = cls._init_jnt_sensors
    if getattr(original, "_lac_rllib_patched", False):
        return

    def _init_jnt_sensors(self) -> None:
        engine = self.engine
        model = engine.model
        engine.model = _IntJointIdModel(model)
        try:
            original(self)
        finally:
            engine.model = model

    _init_jnt_sensors._lac_rllib_patched = True  # type: ignore[attr-defined]
    _init_jnt_sensors.__wrapped__ = original  # type: ignore[attr-defined]
    _init_jnt_sensors.__doc__ = original.__doc__
    cls._init_jnt_sensors = _init_jnt_sensors


# --------------------------------------------------------------------------- patch 6


def _scalar_float(value: Any = 0.0) -> float:
    """``float`` as numpy < 2.4 had it for arrays: a size-1 array gives its single element."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    return float(value)


_scalar_float._lac_rllib_patched = True  # type: ignore[attr-defined]


def _patch_angle_sensor_float() -> None:
    base_agent = importlib.import_module("safety_gymnasium.bases.base_agent")
    if getattr(base_agent.__dict__.get("float"), "_lac_rllib_patched", False):
        return
    base_agent.float = _scalar_float  # shadows the builtin in that module only


# --------------------------------------------------------------------------- registry


def _patch_offscreen_viewer() -> None:
    """Fix 5: safety-gymnasium builds gymnasium's ``OffScreenViewer(model, data)``; gymnasium 1.x
    requires width and height, so offscreen rendering (videos) raised. Default them to the
    model's offscreen buffer size."""
    import safety_gymnasium.bases.underlying as underlying
    from gymnasium.envs.mujoco.mujoco_rendering import OffScreenViewer

    if getattr(underlying.OffScreenViewer, "_lac_rllib_patched", False):
        return

    class SizedOffScreenViewer(OffScreenViewer):
        _lac_rllib_patched = True

        def __init__(self, model, data, width=None, height=None, **kwargs):
            super().__init__(model, data, width or model.vis.global_.offwidth,
                             height or model.vis.global_.offheight, **kwargs)

    underlying.OffScreenViewer = SizedOffScreenViewer


def _is_lac_spec(spec: EnvSpec | None) -> bool:
    from lac_rllib.tasks import registry

    return spec is not None and spec.entry_point is registry._gym_entry_point


@contextlib.contextmanager
def _lac_ids_set_aside() -> Iterator[None]:
    """Take lac-rllib's entries out of gymnasium's registry while safety_gymnasium registers.

    So safety_gymnasium's registrations of the same ids neither warn ("Overriding environment")
    nor stay: they are kept in ``_SAFETY_SPECS`` and ours are put back.
    """
    aside = {k: s for k, s in gym.registry.items() if _is_lac_spec(s)}
    for k in aside:
        del gym.registry[k]
    try:
        yield
    finally:
        for k, spec in aside.items():
            theirs = gym.registry.get(k)
            if theirs is not None and not _is_lac_spec(theirs):
                _SAFETY_SPECS[k] = theirs
            gym.registry[k] = spec


def _reclaim_gym_ids() -> None:
    """Lac-rllib tasks whose gymnasium entry is safety_gymnasium's get ours back.

    Happens when a lac task was registered after safety_gymnasium (``register`` then skips
    gymnasium's registry because the id is taken).
    """
    from lac_rllib.tasks import registry

    safe_registry = sys.modules["safety_gymnasium.utils.registration"].safe_registry
    for env_id in safe_registry.intersection(registry._TASKS):
        current = gym.registry.get(env_id)
        if current is None or _is_lac_spec(current):
            continue
        _SAFETY_SPECS.setdefault(env_id, current)
        gym.registry[env_id] = EnvSpec(
            id=env_id, entry_point=registry._gym_entry_point, kwargs={"task_id": env_id}
        )


# --------------------------------------------------------------------------- public API


def apply() -> types.ModuleType:
    """Apply all patches (idempotent, thread-safe) and return the ``safety_gymnasium`` module."""
    with _LOCK:
        if _STATE["module"] is not None:
            _reclaim_gym_ids()  # cheap; covers lac tasks registered after the first call
            return _STATE["module"]
        # lac-rllib's ids are registered before safety's: importing this module ran
        # lac_rllib/tasks/__init__.py first (Python imports a package before its modules).

        # If something else already imported safety_gymnasium (with its own fixes), the import
        # below is a no-op and only patches 3-4 and the registry fix are added.
        with (
            _lac_ids_set_aside(),
            _temporary_modules(_shim_modules()),
            _lenient_ndarray_dataclass_defaults(),
        ):
            sg = importlib.import_module("safety_gymnasium")
            # Import every module that defines ndarray-default dataclasses while patch 2 is on.
            for name in (
                "safety_gymnasium.builder",
                "safety_gymnasium.assets.geoms",
                "safety_gymnasium.assets.mocaps",
                "safety_gymnasium.assets.free_geoms",
            ):
                importlib.import_module(name)
        _patch_registration()
        _patch_car_joint_ids()
        _patch_angle_sensor_float()
        _patch_offscreen_viewer()
        _reclaim_gym_ids()
        _STATE["module"] = sg
        return sg


def is_applied() -> bool:
    return _STATE["module"] is not None


def safety_spec(env_id: str) -> SafetyEnvSpec:
    """safety_gymnasium's own spec for ``env_id`` (6-tuple env), whatever gymnasium's registry says."""
    apply()
    registration = sys.modules["safety_gymnasium.utils.registration"]
    if env_id not in registration.safe_registry:
        raise ValueError(f"{env_id!r} is not a safety_gymnasium id")
    return registration._find_spec(env_id)
