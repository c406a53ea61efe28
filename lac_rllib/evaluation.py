"""Evaluate a trained LAC checkpoint: restore the policy without Ray, run seeded episodes.

``restore_policy(path)`` reads an RLlib checkpoint written by ``LAC.save_to_path`` (what
``lac-train`` leaves in ``<output>/checkpoint``) with RLlib's own ``Checkpointable`` API, in
this process, without ``ray.init``:

* the FULL ``LACTorchRLModule`` (actor, critics, target actor and critics, ν) from the
  learner's copy ``learner_group/learner/rl_module/default_policy`` via
  ``RLModule.from_checkpoint``. The env runners' copy is inference-only (no critics), and the
  Langevin chain needs the critics, the target actor and ν;
* the env-to-module connector pipeline the env runner acted with, via
  ``EnvToModulePipeline.from_checkpoint(env_runner/env_to_module_connector)``; its
  ``MeanStdFilter`` (running mean/std + clip, docs/spec.md §5) is swapped for a frozen twin
  (``update_stats=False``) holding the same state, so evaluation never moves the statistics;
* the task id and the LAC config fields from the checkpoint's ``rllib_checkpoint.json``,
  which ``SafeAlgorithm.get_metadata`` fills (``checkpoint_format`` 4; formats 2 and 3 are read
  too, where the version matches). The lac-rllib major.minor
  version and the format must match the installed ones;
* its algorithm (``algo``): one of the registry's, or a user's own, imported again by the module
  path it ran under (from the Python path or the working directory: lac_rllib/algorithms/registry.py).

``evaluate(policy, episodes, seed, actions=...)`` runs ``episodes`` episodes, episode ``i``
reset with seed ``seed + i``, fully deterministic for equal seeds. A task run on its batched
backend (``env_backend: batched``, the navigation ids' default) plays up to 10 episodes at a time in
one vector env of that backend, each episode's actions computed alone: the same episodes as one
env plays them, bit for bit (tests/test_evaluation.py), in less time. Video records one env:
Safety-Gymnasium's, which renders.

* ``actions="generator"`` (every algorithm): the policy's deterministic action
  (``module.deterministic_action``: the mean, as the env receives it);
* another mode its algorithm declares (``ACTIONS``; LAC's ``"langevin"``: Algorithm 1 at each
  visited state) is the module's own ``evaluation_action(obs, mode, generator=..., **options)``,
  with noise from a ``torch.Generator`` seeded with ``seed + i`` and the mode's per-state
  diagnostics averaged into the result (``<name>_mean``), beside what the module's
  ``evaluation_info(mode, **options)`` says it ran with. The evaluator knows no algorithm's mode.

Actions are clipped to the action bounds before ``env.step`` (as RLlib's ``clip_actions``
does in training). The episode cost follows the task's convention (sum, or discounted with
``episode_cost_discount``), as in training.

Every failure to restore raises :class:`CheckpointError` with a one-line message.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import math
import os
import sys
from typing import Any

import numpy as np
import torch

from lac_rllib.constrained.algorithm import CHECKPOINT_FORMAT

#: The ``checkpoint_format`` this module reads (lac_rllib.constrained.algorithm writes it), and the
#: older formats it still reads, each with the keys renamed since (old name → current name).
SUPPORTED_CHECKPOINT_FORMAT = CHECKPOINT_FORMAT
OLDER_FORMATS = {2: {"lac_config": "algo_config"}, 3: {}}
#: The modes every algorithm acts with (the others are their modules' own): its deterministic action
#: (the mean), and a sample of its policy as the env runners drew them in training.
GENERATOR, STOCHASTIC = "generator", "stochastic"
#: The RLlib algorithm checkpoint's metadata file (``Algorithm.METADATA_FILE_NAME``).
ALGO_METADATA_FILE = "rllib_checkpoint.json"
#: Frames rendered per episode video at most (longer episodes are subsampled).
MAX_VIDEO_FRAMES = 200


class CheckpointError(Exception):
    """A checkpoint cannot be restored; the message names the problem in one line."""


@dataclasses.dataclass
class Policy:
    """A restored LAC policy: everything ``evaluate`` needs, no Ray."""

    module: Any                   # LACTorchRLModule, full (critics, targets, ν), eval mode
    env_to_module: Any            # EnvToModulePipeline (its MeanStdFilter frozen)
    module_to_env: Any            # ModuleToEnvPipeline: sample, unsquash, clip (the stochastic mode); None: absent
    obs_filter: Any               # the frozen MeanStdFilter, or None (obs_normalization off)
    task_id: str
    algo_config: dict             # the algorithm's fields as saved (LACParams for LAC)
    cost_limit: float             # b in force for the run
    episode_cost_discount: float  # 1.0 = summed episode cost, < 1 = discounted
    env_config: dict
    checkpoint_path: str
    metadata: dict                # the whole rllib_checkpoint.json

    @property
    def constraint_set(self):
        """The run's constraints and limits (its ``constraints`` field), or None: one on ``info["cost"]``."""
        from lac_rllib.tasks import get_task
        from lac_rllib.tasks.constraints import select

        limits = self.algo_config.get("constraints")
        return None if not limits else select(get_task(self.task_id).constraints, limits, task_id=self.task_id)

    @property
    def algo(self) -> str:
        """The algorithm that wrote the checkpoint (lac_rllib/algorithms/registry.py)."""
        from lac_rllib.algorithms.registry import DEFAULT_ALGO

        return str(self.metadata.get("algo") or DEFAULT_ALGO)

    @property
    def actions(self) -> tuple[str, ...]:
        """The action modes this policy can act with (the algorithm's ``ACTIONS``)."""
        from lac_rllib.algorithms.registry import actions

        # A draw from π needs the env runner's module-to-env pipeline (sample, unsquash, clip).
        return tuple(mode for mode in actions(self.algo) if mode != STOCHASTIC or self.module_to_env is not None)

    @property
    def action_low(self) -> np.ndarray:
        return np.asarray(self.module.action_space.low, dtype=np.float32)

    @property
    def action_high(self) -> np.ndarray:
        return np.asarray(self.module.action_space.high, dtype=np.float32)

    def preprocess(self, raw_obs: np.ndarray) -> torch.Tensor:
        """(B, obs_dim) raw env observations → (B, obs_dim) module input (filter applied, frozen)."""
        from ray.rllib.core.columns import Columns
        from ray.rllib.env.single_agent_episode import SingleAgentEpisode

        space = self.env_to_module.input_observation_space
        episodes = [SingleAgentEpisode(observations=[np.asarray(o, dtype=np.float32)],
                                       observation_space=space,
                                       action_space=self.env_to_module.input_action_space)
                    for o in np.atleast_2d(raw_obs)]
        batch = self.env_to_module(episodes=episodes, rl_module=self.module, explore=False,
                                   shared_data={})
        return batch[Columns.OBS]


# ----------------------------------------------------------------------------- restore


def _installed_version() -> str:
    return importlib.metadata.version("lac-rllib")


def _major_minor(version: str) -> tuple[str, ...]:
    return tuple(str(version).split(".")[:2])


def find_checkpoint_dir(path: str) -> str:
    """The algorithm checkpoint directory: ``path`` itself or ``path/checkpoint`` (a
    ``lac-train --output`` directory)."""
    path = os.path.abspath(os.path.expanduser(str(path)))
    if not os.path.exists(path):
        raise CheckpointError(f"checkpoint not found: {path} does not exist")
    if not os.path.isdir(path):
        raise CheckpointError(f"not a checkpoint: {path} is not a directory")
    for candidate in (path, os.path.join(path, "checkpoint")):
        if os.path.isfile(os.path.join(candidate, ALGO_METADATA_FILE)):
            return candidate
    raise CheckpointError(
        f"not an RLlib checkpoint: {path} has no {ALGO_METADATA_FILE} (nor checkpoint/{ALGO_METADATA_FILE})")


def read_metadata(checkpoint_dir: str) -> dict:
    """Read and check the LAC keys of ``rllib_checkpoint.json`` (version, format, task)."""
    file = os.path.join(checkpoint_dir, ALGO_METADATA_FILE)
    try:
        with open(file, encoding="utf-8") as f:
            meta = json.load(f)
        if not isinstance(meta, dict):
            raise ValueError(f"top level is {type(meta).__name__}, not an object")
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise CheckpointError(f"corrupt checkpoint: metadata {file} is unreadable ({one_line(e)})") from None
    if "lac_rllib_version" not in meta or "checkpoint_format" not in meta:
        raise CheckpointError(
            f"not a lac-rllib checkpoint: {file} has no lac_rllib_version/checkpoint_format "
            "(written by another algorithm, or by lac-rllib before checkpoint format 1)")
    fmt, saved, installed = meta["checkpoint_format"], str(meta["lac_rllib_version"]), _installed_version()
    if fmt != SUPPORTED_CHECKPOINT_FORMAT and fmt not in OLDER_FORMATS:
        readable = " and ".join(map(str, (SUPPORTED_CHECKPOINT_FORMAT, *OLDER_FORMATS)))
        raise CheckpointError(
            f"unsupported checkpoint format {fmt!r} in {file} (written by lac-rllib {saved}): this lac-rllib "
            f"{installed} reads formats {readable}")
    for old, new in OLDER_FORMATS.get(fmt, {}).items():
        if old in meta:
            meta[new] = meta.pop(old)
    if _major_minor(saved) != _major_minor(installed):
        raise CheckpointError(
            f"checkpoint version mismatch: written by lac-rllib {saved}, installed lac-rllib is "
            f"{installed} (major.minor must match; evaluate it with lac-rllib "
            f"{'.'.join(_major_minor(saved))}.x)")
    for key in ("task_id", "algo_config", "cost_limit", "episode_cost_discount"):
        if key not in meta:
            raise CheckpointError(f"corrupt checkpoint: {file} lacks the {key!r} entry")
    return meta


def _restore_module(module_dir: str):
    """The learner's full RLModule, every parameter and buffer restored (or CheckpointError)."""
    from ray.rllib.core.rl_module.apis import TargetNetworkAPI
    from ray.rllib.core.rl_module.rl_module import RLModule

    if not os.path.isdir(module_dir):
        raise CheckpointError(f"corrupt checkpoint: module directory {module_dir} is missing")
    try:
        module = RLModule.from_checkpoint(module_dir)
        if module.inference_only:
            raise CheckpointError(f"corrupt checkpoint: {module_dir} holds an inference-only module "
                                  "(no critics); the learner's full module is required")
        # Target networks are created by the Learner, not by the module's setup(); RLlib's
        # TorchRLModule.set_state loads non-strictly and would silently skip π_φ' and Q'.
        # So create them, poison every tensor with NaN and restore again: any tensor the
        # checkpoint does not cover stays NaN and is reported below.
        if isinstance(module, TargetNetworkAPI):
            module.make_target_networks()
        with torch.no_grad():
            for t in list(module.parameters()) + list(module.buffers()):
                t.fill_(float("nan"))
        module.restore_from_path(module_dir)
    except CheckpointError:
        raise
    except Exception as e:  # unpickling/IO errors of every kind
        raise CheckpointError(f"corrupt checkpoint: cannot restore the RLModule from {module_dir} "
                              f"({one_line(e)})") from None
    tensors = list(module.named_parameters()) + list(module.named_buffers())
    bad = [name for name, t in tensors if not torch.isfinite(t).all()]
    if bad:
        raise CheckpointError(
            f"corrupt checkpoint: module state in {module_dir} is missing or non-finite for "
            f"{len(bad)} tensor(s), e.g. {', '.join(bad[:3])}")
    module.eval()
    return module


def _restore_env_to_module(pipeline_dir: str):
    """The env runner's env-to-module pipeline with a frozen copy of its MeanStdFilter."""
    from ray.rllib.connectors.env_to_module.env_to_module_pipeline import EnvToModulePipeline
    from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter

    if not os.path.isdir(pipeline_dir):
        raise CheckpointError(f"corrupt checkpoint: observation-filter directory {pipeline_dir} is missing")
    try:
        pipeline = EnvToModulePipeline.from_checkpoint(pipeline_dir)
        filters = pipeline[MeanStdFilter]
        if len(filters) > 1:
            raise CheckpointError(f"unexpected checkpoint: {len(filters)} MeanStdFilters in {pipeline_dir}")
        frozen = None
        if filters:
            trained = filters[0]
            _, ctor_kwargs = trained.get_ctor_args_and_kwargs()
            cls = type(trained)  # LAC's FlooredMeanStdFilter (older checkpoints: RLlib's own)
            frozen = cls(**{**ctor_kwargs, "update_stats": False})
            # insert_after sets the frozen filter's spaces; remove() drops the first filter of
            # exactly this class, i.e. the trained one.
            pipeline.insert_after(cls, frozen)
            frozen.set_state(trained.get_state())
            pipeline.remove(cls)
    except CheckpointError:
        raise
    except Exception as e:  # connector unpickling/IO errors of every kind
        raise CheckpointError(f"corrupt checkpoint: cannot restore the observation filter from "
                              f"{pipeline_dir} ({one_line(e)})") from None
    return pipeline, frozen


def _restore_module_to_env(pipeline_dir: str):
    """The env runner's module-to-env pipeline (it samples the action from the policy's
    distribution, unsquashes and clips it, as in training), or None where a checkpoint has none."""
    from ray.rllib.connectors.module_to_env.module_to_env_pipeline import ModuleToEnvPipeline

    if not os.path.isdir(pipeline_dir):
        return None
    try:
        return ModuleToEnvPipeline.from_checkpoint(pipeline_dir)
    except Exception as e:  # connector unpickling/IO errors of every kind
        raise CheckpointError(f"corrupt checkpoint: cannot restore the action pipeline from {pipeline_dir} "
                              f"({one_line(e)})") from None


def restore_policy(checkpoint_path: str) -> Policy:
    """Restore the LAC policy of an RLlib checkpoint (see the module docstring). No Ray."""
    from ray.rllib.core import (
        COMPONENT_ENV_RUNNER,
        COMPONENT_ENV_TO_MODULE_CONNECTOR,
        COMPONENT_LEARNER,
        COMPONENT_LEARNER_GROUP,
        COMPONENT_MODULE_TO_ENV_CONNECTOR,
        COMPONENT_RL_MODULE,
        DEFAULT_MODULE_ID,
    )

    from lac_rllib.algorithms.registry import DEFAULT_ALGO, check_algo
    from lac_rllib.tasks import get_task, known_tasks
    from lac_rllib.tasks.user import register_definition

    ckpt = find_checkpoint_dir(checkpoint_path)
    meta = read_metadata(ckpt)
    try:  # a user's algorithm is imported again by the path it ran under (the checkpoint's algo)
        check_algo(meta.get("algo") or DEFAULT_ALGO, (os.getcwd(),))
    except ValueError as e:
        raise CheckpointError(f"checkpoint algorithm is not available here: {one_line(str(e))}") from None
    if meta.get("task_definition") and meta["task_id"] not in known_tasks():
        register_definition(meta["task_definition"])  # a user's env: its spec is in the checkpoint
    try:
        get_task(meta["task_id"])
    except ValueError as e:
        raise CheckpointError(f"checkpoint task is not available here: {one_line(e)}") from None
    module = _restore_module(os.path.join(
        ckpt, COMPONENT_LEARNER_GROUP, COMPONENT_LEARNER, COMPONENT_RL_MODULE, DEFAULT_MODULE_ID))
    pipeline, obs_filter = _restore_env_to_module(
        os.path.join(ckpt, COMPONENT_ENV_RUNNER, COMPONENT_ENV_TO_MODULE_CONNECTOR))
    if meta["algo_config"].get("obs_normalization", True) and obs_filter is None:
        raise CheckpointError(f"corrupt checkpoint: obs_normalization is on but {ckpt} holds no MeanStdFilter state")
    return Policy(
        module=module, env_to_module=pipeline, module_to_env=_restore_module_to_env(
            os.path.join(ckpt, COMPONENT_ENV_RUNNER, COMPONENT_MODULE_TO_ENV_CONNECTOR)),
        obs_filter=obs_filter, task_id=meta["task_id"],
        algo_config=dict(meta["algo_config"]), cost_limit=float(meta["cost_limit"]),
        episode_cost_discount=float(meta["episode_cost_discount"]),
        env_config=dict(meta.get("env_config") or {}), checkpoint_path=ckpt, metadata=meta,
    )


def one_line(e: BaseException | str) -> str:
    text = " ".join(str(e).split())
    if isinstance(e, BaseException):
        text = f"{type(e).__name__}: {text}" if text else type(e).__name__
    return text[:300]


# ----------------------------------------------------------------------------- evaluate


class _Progress:
    """tqdm when installed, else a plain counter on stderr."""

    def __init__(self, total: int, desc: str, enabled: bool):
        self._bar, self._n, self._total, self._desc, self._enabled = None, 0, total, desc, enabled
        if not enabled:
            return
        try:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit="ep", file=sys.stderr, dynamic_ncols=True)
        except ImportError:
            pass

    def update(self, **postfix) -> None:
        self._n += 1
        if self._bar is not None:
            self._bar.set_postfix(postfix, refresh=False)
            self._bar.update(1)
        elif self._enabled:
            info = "  ".join(f"{k} {v}" for k, v in postfix.items())
            print(f"\r{self._desc}: {self._n}/{self._total}  {info}", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
        elif self._enabled:
            print(file=sys.stderr, flush=True)


def _notice(msg: str) -> None:
    print(f"evaluate: notice: {msg}", file=sys.stderr, flush=True)


def _video_env(policy: Policy):
    """(env with rgb_array rendering, None) or (None, reason it cannot render here)."""
    from lac_rllib.tasks import get_task

    spec = get_task(policy.task_id)
    probe = spec.make(dict(policy.env_config))
    modes = (getattr(probe, "metadata", None) or {}).get("render_modes", [])
    probe.close()
    if "rgb_array" not in modes:
        return None, (f"task {policy.task_id} has no renderer (render modes: {list(modes) or 'none'}); "
                      "continuing without video")
    # MuJoCo picks its GL backend when first imported: headless EGL unless the user chose.
    os.environ.setdefault("MUJOCO_GL", "egl")
    if os.environ["MUJOCO_GL"] in ("egl", "osmesa"):
        os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    try:
        env = spec.make({**policy.env_config, "render_mode": "rgb_array"})
        env.reset(seed=0)
        frame = env.render()
        if not isinstance(frame, np.ndarray) or frame.ndim != 3:
            raise RuntimeError(f"render() returned {type(frame).__name__}")
    except Exception as e:  # every GL failure mode
        return None, (f"cannot render {policy.task_id} offscreen here (MUJOCO_GL="
                      f"{os.environ.get('MUJOCO_GL')}: {one_line(e)[:160]}); continuing without video")
    return env, None


class _Recorder:
    """Captures every ``stride``-th frame, at most ~MAX_VIDEO_FRAMES per episode, ≤ ~320 px.

    The stride comes from the env's time limit; without one, when 2·MAX_VIDEO_FRAMES frames
    are held every other one is dropped and the stride doubles. Offscreen rendering is the
    expensive part (software EGL renders ~0.2 s per 480² frame), hence the budget.
    """

    def __init__(self, env):
        limit = _episode_limit(env)
        self.env, self.frames = env, []
        self.stride = max(1, math.ceil(limit / MAX_VIDEO_FRAMES)) if limit else 1

    def capture(self, t: int, force: bool = False) -> None:
        if t % self.stride and not force:
            return
        frame = np.asarray(self.env.render())
        step = max(1, math.ceil(max(frame.shape[:2]) / 320))
        self.frames.append(np.ascontiguousarray(frame[::step, ::step]))
        if len(self.frames) >= 2 * MAX_VIDEO_FRAMES:
            self.frames, self.stride = self.frames[::2], self.stride * 2


def _episode_limit(env) -> int | None:
    """The TimeLimit of an env (walking its wrappers), or None."""
    e = env
    while e is not None:
        n = getattr(e, "_max_episode_steps", None)
        if isinstance(n, int) and n > 0:
            return n
        e = getattr(e, "env", None)
    return getattr(getattr(env, "spec", None), "max_episode_steps", None)


def _write_video(frames: list[np.ndarray], path_stem: str, fps: float) -> str:
    """mp4 when an ffmpeg plugin is installed (imageio-ffmpeg or av), else gif."""
    import imageio.v2 as imageio

    for module, ext in (("imageio_ffmpeg", ".mp4"), ("av", ".mp4")):
        try:
            __import__(module)
        except ImportError:
            continue
        path = path_stem + ext
        imageio.mimwrite(path, frames, fps=fps, macro_block_size=1)
        return path
    path = path_stem + ".gif"
    imageio.mimwrite(path, frames, duration=1000.0 / fps, loop=0)
    return path


def _stats(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    arr = np.asarray(values, dtype=np.float64)
    return float(arr.mean()), float(arr.std())


def _sampled_action(policy: Policy, obs: torch.Tensor, episode, shared: dict) -> torch.Tensor:
    """A sample of the policy at ``obs`` as the env runners drew it in training: the module's
    exploration forward, then the checkpoint's module-to-env pipeline (the action sampled from its
    distribution, unsquashed onto the bounds and clipped where the config says)."""
    from ray.rllib.core.columns import Columns

    out = policy.module.forward_exploration({Columns.OBS: obs})
    to_env = policy.module_to_env(rl_module=policy.module, batch=dict(out), episodes=[episode], explore=True,
                                  shared_data=shared)
    action = to_env.get(Columns.ACTIONS_FOR_ENV, to_env[Columns.ACTIONS])
    return torch.as_tensor(np.asarray(action, dtype=np.float32)).reshape(1, -1)


#: Episodes an evaluation plays together, at most, on a task's batched backend (one vector env).
EVAL_LANES = 10


def _lanes(policy: Policy, episodes: int) -> int:
    """How many episodes to play together: 1 (one env), or on a task run on its batched backend
    (``env_backend: batched``) up to :data:`EVAL_LANES`, in groups as even as they come."""
    from lac_rllib.tasks import get_task

    if not get_task(policy.task_id).batched or policy.env_config.get("env_backend", "batched") != "batched":
        return 1
    groups = math.ceil(episodes / EVAL_LANES)
    return math.ceil(episodes / groups)


@dataclasses.dataclass
class _Lane:
    """One episode of a group being played: its RLlib episode, its noise and its tallies."""

    episode: Any                # SingleAgentEpisode: what the env-to-module pipeline reads
    generator: torch.Generator  # a mode's own noise (LAC's chain), seeded with the episode's seed
    rng: torch.Tensor           # torch's global RNG state of this episode (the stochastic mode's samples)
    ret: float = 0.0
    cost: float = 0.0
    t: int = 0
    done: bool = False
    constraint_costs: Any = None  # with constraints: each one's episode cost so far


class _Envs:
    """One env (``width`` 1) or a vector env of ``width`` envs, each env k playing one episode of a
    group: reset with ``seed + k`` (the vector env's own seeding), stepped with its episode's
    actions until it ends, then left out. On the batched backend each env is stock
    Safety-Gymnasium step for step (docs/speed/batched-equality.md), and each episode's actions are
    computed alone, as with one env: the same episodes, several at a time."""

    def __init__(self, env, width: int) -> None:
        self.env, self.width = env, width

    def reset(self, seed: int) -> list[tuple]:
        if self.width == 1:
            return [self.env.reset(seed=seed)]
        obs, infos = self.env.reset(seed=seed)
        return [(obs[k], _env_info(infos, k)) for k in range(self.width)]

    def step(self, chosen: dict[int, np.ndarray]) -> dict[int, tuple]:
        """``chosen``: env k → its action, for the envs still playing; their step, by env."""
        if self.width == 1:
            return {0: self.env.step(chosen[0])}
        batch = np.zeros(self.env.action_space.shape, self.env.action_space.dtype)
        for k, action in chosen.items():
            batch[k] = action
        obs, rewards, terminated, truncated, infos = self.env.step(batch)
        return {k: (obs[k], rewards[k], terminated[k], truncated[k], _env_info(infos, k)) for k in chosen}


def _env_info(infos: dict, k: int) -> dict:
    """Env ``k``'s info from a vector env's infos (gymnasium's dict of arrays, ``_key`` masks)."""
    return {key: value[k] for key, value in infos.items()
            if not key.startswith("_") and infos.get(f"_{key}", np.ones(k + 1, bool))[k]}


def evaluate(policy: Policy, episodes: int, seed: int, actions: str = GENERATOR,
             langevin_steps: int | None = None, langevin_step_size: float | None = None,
             video_dir: str | None = None, progress: bool = True) -> dict:
    """Run ``episodes`` episodes (episode i reset with ``seed + i``) and summarise them.

    Returns per-episode ``returns``/``costs``/``lengths``, ``return_mean``/``return_std``,
    ``cost_mean``/``cost_std`` (std over episodes, ddof 0), ``cost_limit``,
    ``within_limit_fraction`` (episodes with cost ≤ b); a run with ``constraints``, ``constraints``:
    name → that constraint's ``costs``, ``cost_mean``, ``cost_std``, ``cost_limit`` and
    ``within_limit_fraction``, and ``within_all_limits_fraction`` (episodes within every limit: the
    joint rule; with one constraint ``costs`` are its own); and for a mode of the module's own its
    diagnostics' means over all visited states and ``evaluation_info`` (LAC's ``"langevin"``:
    ``energy_generator_mean`` (E at the chain start ã₀ ~ π_φ'), ``energy_refined_mean`` (E at
    ã_T), ``action_displacement_mean``; T, η and ν). ``langevin_steps``/``langevin_step_size``
    are lac-eval's options of that mode (``steps``/``step_size`` of LAC's ``evaluation_action``).
    """
    from ray.rllib.core.columns import Columns
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    from lac_rllib.constrained.costs import step_cost
    from lac_rllib.tasks import get_task

    if actions not in policy.actions:
        raise ValueError(f"actions={actions!r} is not a mode of this checkpoint's algorithm ({policy.algo}); "
                         f"accepted: {' | '.join(policy.actions)}")
    if not (isinstance(episodes, int) and episodes >= 1):
        raise ValueError(f"episodes={episodes!r} is invalid; accepted: an integer >= 1")
    if langevin_steps is not None and not (isinstance(langevin_steps, int) and langevin_steps >= 1):
        raise ValueError(f"langevin_steps={langevin_steps!r} is invalid; accepted: an integer >= 1")
    if langevin_step_size is not None and not (math.isfinite(langevin_step_size) and langevin_step_size > 0):
        raise ValueError(f"langevin_step_size={langevin_step_size!r} is invalid; accepted: a number > 0")
    options = {k: v for k, v in (("steps", langevin_steps), ("step_size", langevin_step_size)) if v is not None}
    if options and actions == GENERATOR:
        raise ValueError("langevin_steps/langevin_step_size are options of a chain mode, not of actions='generator'")

    module, gamma_c, several = policy.module, policy.episode_cost_discount, policy.constraint_set
    low, high = policy.action_low, policy.action_high
    env, video_notice, videos = None, None, []
    if video_dir is not None:
        env, video_notice = _video_env(policy)
        if video_notice:
            _notice(video_notice)
        else:
            os.makedirs(video_dir, exist_ok=True)
    width = 1 if env is not None else _lanes(policy, episodes)
    if env is None:
        config = dict(policy.env_config) | ({"num_envs": width} if width > 1 else {})
        env = get_task(policy.task_id).make(config)
    envs = _Envs(env, width)
    fps = float((env.metadata or {}).get("render_fps") or 30)
    video = video_notice is None and video_dir is not None  # one env then (width 1), an episode at a time

    returns, costs, lengths, per_constraint = [], [], [], []
    diagnostics: dict[str, list[float]] = {}
    bar = _Progress(episodes, f"eval {actions}", progress)
    rng_state = torch.random.get_rng_state()  # the stochastic mode seeds torch per episode; restored after
    try:
        for first in range(0, episodes, width):
            group = []  # episodes first.. of this group, episode i on env i - first, reset with seed + i
            recorder = _Recorder(env) if video else None
            for k, (obs, info) in enumerate(envs.reset(seed + first)[:episodes - first]):
                torch.manual_seed(seed + first + k)  # the stochastic mode's samples (RLlib's, from torch's global RNG)
                group.append(_Lane(
                    episode=SingleAgentEpisode(observations=[obs], infos=[info],
                                               observation_space=policy.env_to_module.input_observation_space,
                                               action_space=policy.env_to_module.input_action_space),
                    generator=torch.Generator().manual_seed(seed + first + k),  # a mode's noise
                    rng=torch.random.get_rng_state(),
                    constraint_costs=None if several is None else np.zeros(len(several))))
            while not all(lane.done for lane in group):
                chosen = {}
                for k, lane in enumerate(group):
                    if lane.done:
                        continue
                    if recorder is not None:
                        recorder.capture(lane.t)
                    torch.random.set_rng_state(lane.rng)  # this episode's own stream of torch's global RNG
                    shared = {}  # what the env-to-module pipeline leaves for the module-to-env one
                    batch = policy.env_to_module(episodes=[lane.episode], rl_module=module,
                                                 explore=actions == STOCHASTIC, shared_data=shared)
                    s = batch[Columns.OBS]
                    with torch.no_grad():
                        if actions == GENERATOR:
                            action = module.deterministic_action(s)
                        elif actions == STOCHASTIC:
                            action = _sampled_action(policy, s, lane.episode, shared)
                        else:  # the module's own mode (ACTIONS)
                            action, diag = module.evaluation_action(s, actions, generator=lane.generator, **options)
                            for name, value in diag.items():
                                diagnostics.setdefault(name, []).append(value)
                    lane.rng = torch.random.get_rng_state()
                    chosen[k] = np.clip(action[0].numpy().astype(np.float32), low, high)
                for k, (obs, reward, terminated, truncated, info) in envs.step(chosen).items():
                    lane = group[k]
                    lane.ret += float(reward)
                    if several is None:
                        lane.cost += gamma_c**lane.t * step_cost(info)  # the task's convention, as in training
                    else:  # each constraint's cost; with one, that is the run's cost, as in training
                        lane.constraint_costs += gamma_c**lane.t * several.step_costs(info)
                        lane.cost += gamma_c**lane.t * (step_cost(info) if len(several) > 1
                                                        else float(several.step_costs(info)[0]))
                    lane.t += 1
                    lane.done = bool(terminated or truncated)
                    lane.episode.add_env_step(obs, chosen[k], float(reward), infos=info,
                                              terminated=bool(terminated), truncated=bool(truncated))
            for k, lane in enumerate(group):
                i = first + k
                returns.append(lane.ret)
                costs.append(lane.cost)
                lengths.append(lane.t)
                if several is not None:
                    per_constraint.append(lane.constraint_costs.tolist())
                if recorder is not None:
                    recorder.capture(lane.t, force=True)
                    videos.append(_write_video(recorder.frames, os.path.join(
                        video_dir, f"episode_{i:03d}_seed_{seed + i}_{actions}"), fps / recorder.stride))
                bar.update(ret=f"{lane.ret:.3g}", cost=f"{lane.cost:.3g}")
    finally:
        torch.random.set_rng_state(rng_state)
        bar.close()
        env.close()

    limit = policy.cost_limit
    ret_mean, ret_std = _stats(returns)
    cost_mean, cost_std = _stats(costs)
    result = {
        "checkpoint": policy.checkpoint_path, "task": policy.task_id, "algo": policy.algo, "actions": actions,
        "episodes": episodes, "seed": seed,
        "returns": returns, "costs": costs, "lengths": lengths,
        "return_mean": ret_mean, "return_std": ret_std, "cost_mean": cost_mean, "cost_std": cost_std,
        "cost_limit": limit, "episode_cost_discount": gamma_c,
        "within_limit_fraction": float(np.mean([c <= limit for c in costs])),
        "videos": videos, "video_notice": video_notice,
    }
    if several is not None:
        table = np.asarray(per_constraint, dtype=float).reshape(len(per_constraint), len(several))
        result["constraints"] = {}
        for k, (name, b) in enumerate(zip(several.names, several.limits)):
            mean, std = _stats(table[:, k].tolist())
            result["constraints"][name] = {
                "costs": table[:, k].tolist(), "cost_mean": mean, "cost_std": std, "cost_limit": b,
                "within_limit_fraction": float(np.mean(table[:, k] <= b))}
        result["within_all_limits_fraction"] = float(np.mean((table <= np.asarray(several.limits)).all(axis=1)))
    if actions not in (GENERATOR, STOCHASTIC):  # the module's own mode: what it ran with
        result.update(module.evaluation_info(actions, **options))
        result.update({f"{name}_mean": float(np.mean(values)) for name, values in diagnostics.items()})
    return result
