"""The plan's estimate: what a trial costs, the plan's figures, and their calibration on this machine.

A trial's seconds are Ray's start-up, its env steps at its task preset's measured rate (``RATE``,
the env's share scaled by the task's step cost), its algorithm's own update seconds per env step
(``plan_update_s`` in its folder, read through the registry) and its evaluation blocks. The plan
(sweeps/plan.py) adds them up into its figures (:func:`estimate`): each trial's seconds, the wall
time at its concurrency, the CPU-hours and the evaluation's share.

The rates were measured on one machine; a trial on another runs faster or slower by a factor that
depends on its CPU (AVX2 or AVX512 torch kernels, clock, cache). The estimate is multiplied by
that factor (:func:`machine_factor`), taken, in this order, from:

1. **earlier trials in the same MLflow store** (:func:`store_factor`): the median over up to 200
   finished trials of their run's span over what the rates said for them, at least
   ``MIN_TRIALS`` of them, per algorithm where it has that many (the rates are further off for
   some algorithms than others). The store usually lives on the machine that ran them, and they
   ran the same code: the best witness, though of the load the machine had then;
2. **a probe** (:func:`probe_factor`): ~0.15 s of the work a trial does, 2,000 steps of the tiny
   task's numpy env and 60 Adam steps of a (256, 256) MLP on one torch thread, the fastest of 3,
   timed here against ``PROBE_REFERENCE_S``, its time on a machine where the rates hold.

``LAC_SWEEP_CALIBRATION`` = ``store`` | ``probe`` | ``off`` restricts the sources (``off``: the
rates as they are, factor 1; the tests set it, so plans do not depend on the machine running them).
How close the estimate came on two kinds of CPU: docs/sweeps.md, "What the plan's estimate is".
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import statistics
import time
from typing import TYPE_CHECKING, Callable

from lac_rllib.algorithms.registry import ALGO_FIELD, DEFAULT_ALGO, plan_update_s

if TYPE_CHECKING:
    from sweeps.sweep_file import SweepFile

# The plan's estimate, per preset: env steps per second of one trial on 1 CPU, sampling and the
# update's part every algorithm has (calibration: docs/sweeps.md); each algorithm adds its own
# update's seconds per env step (``plan_update_s`` in its folder, read through the registry).
RATE = {"tiny": 405.0, "safety_gym": 377.0, "mujoco": 185.0}
STARTUP_S = 15.0
#: The envs per runner each preset's RATE holds at (the presets' own: the tiny task's quick trials
#: and the Safety-Gymnasium presets sample 10 envs per runner, the MuJoCo presets 5).
RATE_ENVS = {"tiny": 10, "safety_gym": 10, "mujoco": 5}
#: The env's share of a sampled step's time at one env per runner; the rest (the policy's forward,
#: RLlib's per-step work) a vector env of N envs divides by N. From PointGoal1's sampling, 202 steps/s
#: at one env and 450 at ten (docs/speed.md, "Sampling"): s + (1 - s)/10 = 202/450. A task's
#: ``step_cost`` scales this share.
ENV_SHARE = 0.39
#: The same share in an evaluation block (one env, the policy's forward a step, none of RLlib's
#: sampling machinery): PointButton1's blocks took 2.7x PointGoal1's at a step cost of 3.3 in the
#: table2 quick sweep (docs/sweeps.md, "What the plan's estimate is").
EVAL_ENV_SHARE = 0.75

#: Earlier trials needed before the store's factor is trusted over the probe.
MIN_TRIALS = 3
#: The probe's seconds on a machine where the plan's rates hold. Derived, not measured there: the
#: rates were measured on an AVX2 machine no longer at hand (its default ablation of 21 trials took
#: 27 min 13 s against their ~26 min), and on the AMD EPYC with AVX512-BF16 that took 11 min 31 s
#: for the 24 trials the rates put at 29.9 min (0.386x), the probe takes 0.15 s: 0.15 / 0.386.
PROBE_REFERENCE_S = 0.39
#: The environment variable that restricts the sources (module docstring).
ENV = "LAC_SWEEP_CALIBRATION"
SOURCES = ("auto", "store", "probe", "off")


def seconds_per_env_step(task: str, envs: int | None = None) -> float:
    """Rough seconds of one sampled env step of ``task`` at ``envs`` envs per runner (None: the
    rate's own): its preset's rate, the env's share scaled by the task's ``step_cost`` (a Button1
    step costs ~3 Goal1 steps), the rest divided over the vector env's envs."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    ref = RATE_ENVS.get(spec.preset, 1)
    n = envs or ref
    at = (ENV_SHARE * spec.step_cost + (1 - ENV_SHARE) / n) / (ENV_SHARE + (1 - ENV_SHARE) / ref)
    return at / _rate(spec.preset)


def eval_seconds_per_env_step(task: str) -> float:
    """Rough seconds of one evaluation step of ``task``: its preset's rate, the env's share
    (``EVAL_ENV_SHARE``) scaled by the task's ``step_cost``."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    return (1 + EVAL_ENV_SHARE * (spec.step_cost - 1)) / _rate(spec.preset)


def _rate(preset: str) -> float:
    """``RATE`` of ``preset``; an unknown preset (a user env's) gets the slowest."""
    return RATE.get(preset, min(RATE.values()))


def estimate_trial_s(task: str, steps: int, params: dict, cpus: int) -> float:
    """Rough wall seconds of one trial of ``steps`` env steps whose fields are ``params``
    (``spaces.trial_params``): start-up, then env steps at the task's rate
    (:func:`seconds_per_env_step`), plus the algorithm's own update share (LAC's chain grows with
    T; measured on this project's 2-core machine)."""
    from lac_rllib.tasks import get_task

    sampling = steps * seconds_per_env_step(task, params.get("num_envs_per_env_runner"))
    extra = plan_update_s(params.get(ALGO_FIELD, DEFAULT_ALGO), params, get_task(task).preset) * steps
    return STARTUP_S + (sampling + extra) / cpus ** 0.5


def estimate_eval_s(task: str, steps: int, params: dict, sweep: SweepFile) -> float:
    """Rough seconds of a trial's evaluation blocks (sweeps/trainable.py): ``eval_episodes``
    episodes per mode its algorithm has, at the end and every ``eval_every`` iterations, at the
    task's evaluation rate (:func:`eval_seconds_per_env_step`: one env, a policy forward a step)."""
    from lac_rllib.algorithms.registry import actions
    from lac_rllib.tasks import get_task

    episodes = 10 if sweep.eval_episodes is None else sweep.eval_episodes
    if not episodes:
        return 0.0
    algo = params.get(ALGO_FIELD, DEFAULT_ALGO)
    modes = [m for m in sweep.eval_modes or ("generator", "stochastic") if m == "stochastic" or m in actions(algo)]
    per_iteration = params.get("env_steps_per_iteration") or params.get("train_batch_size_per_learner") or 0
    blocks = 1 + (int(steps // per_iteration) // sweep.eval_every if sweep.eval_every and per_iteration else 0)
    # Each episode counted at the task's episode limit (TaskSpec.episode_steps; episodes may end sooner).
    return blocks * len(modes) * episodes * get_task(task).episode_steps * eval_seconds_per_env_step(task)


def nominal_trial_s(params: dict) -> float | None:
    """What the rates say an earlier trial (its MLflow params, as logged) took, to set against its
    run's span (:func:`machine_factor`); None: not comparable."""
    from sweeps.tracking import P_TASK, P_TIMESTEPS, param_value

    try:
        fields = {k: param_value(v) for k, v in params.items()}
        cpus = int(fields.get("torch_threads", 1))  # a trial's threads are its CPUs (sweeps/trainable.py)
        return estimate_trial_s(str(fields[P_TASK]), int(fields[P_TIMESTEPS]), fields, cpus)
    except Exception:  # a run of another version, a task not registered here: leave it out
        return None


def estimate_wall_s(per_trial: list[float], concurrency: int) -> float:
    """Trials taken longest first onto ``concurrency`` slots (Tune starts them in grid order, so
    this is a floor when the longest come last)."""
    slots = [0.0] * concurrency
    for t in sorted(per_trial, reverse=True):
        slots[slots.index(min(slots))] += t
    return max(slots)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """The plan's figures: what its trials cost at its concurrency, on this machine."""

    trial_seconds: tuple[float, ...]  #: each trial's seconds, calibrated, its evaluation blocks included
    wall_s: float  #: at the plan's concurrency (:func:`estimate_wall_s`)
    cpu_h: float
    eval_share: float  #: the evaluation blocks' share of the trials' time
    calibration: tuple  #: (factor, what it came from): :func:`machine_factor`


def estimate(trials: list, sweep: SweepFile, cpus: int, concurrency: int, tracking_uri: str) -> Estimate:
    """The figures of ``trials`` (``spaces.TrialSpec``; a search's: its first configuration's, once
    per trial) of ``sweep`` at ``cpus`` CPUs each and ``concurrency`` at a time, calibrated on this
    machine from the store at ``tracking_uri`` or a probe."""
    calibration = machine_factor(tracking_uri, sweep.experiment, nominal_trial_s)
    evals = [estimate_eval_s(t.task, t.timesteps, t.params, sweep) for t in trials]
    per_trial = [calibration(t.algo) * (estimate_trial_s(t.task, t.timesteps, t.params, cpus) + e)
                 for t, e in zip(trials, evals)]
    spent, total = sum(calibration(t.algo) * e for t, e in zip(trials, evals)), sum(per_trial)
    return Estimate(trial_seconds=tuple(per_trial), wall_s=estimate_wall_s(per_trial, concurrency),
                    cpu_h=total * cpus / 3600, eval_share=spent / total if total else 0.0,
                    calibration=(calibration.factor, calibration.source))


def duration_text(seconds: float) -> str:
    """A rough duration as the plan prints it: seconds below a minute (a smoke sweep's ~40 s would
    read "~0 min"), whole minutes above."""
    return f"~{seconds:.0f} s" if round(seconds) < 60 else f"~{seconds / 60:.0f} min"


# The calibration: this machine's speed against the rates' (module docstring).

def mode() -> str:
    """The sources allowed (``LAC_SWEEP_CALIBRATION``; default ``auto``: the store, else the probe)."""
    value = os.environ.get(ENV, "auto").strip().lower() or "auto"
    if value not in SOURCES:
        raise ValueError(f"{ENV}={value!r}; accepted: {' | '.join(SOURCES)}")
    return value


def probe_seconds(repeats: int = 3) -> float:
    """The fastest of ``repeats`` runs of the probe's fixed work (module docstring), in seconds."""
    import numpy as np
    import torch

    from lac_rllib.tasks.point_hazard import PointHazardEnv

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a trial's learner thread per CPU (cpus.py): time one
    try:
        best = math.inf
        for _ in range(repeats):
            gen = torch.Generator().manual_seed(0)
            net = torch.nn.Sequential(torch.nn.Linear(32, 256), torch.nn.Tanh(), torch.nn.Linear(256, 256),
                                      torch.nn.Tanh(), torch.nn.Linear(256, 1))
            opt = torch.optim.Adam(net.parameters(), lr=1e-3)
            x, y = torch.randn(256, 32, generator=gen), torch.randn(256, 1, generator=gen)
            env, rng = PointHazardEnv(), np.random.default_rng(0)
            start = time.perf_counter()
            env.reset(seed=0)
            for _ in range(2_000):
                _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, size=2))
                if terminated or truncated:
                    env.reset()
            for _ in range(60):
                opt.zero_grad()
                ((net(x) - y) ** 2).mean().backward()
                opt.step()
            best = min(best, time.perf_counter() - start)
        return best
    finally:
        torch.set_num_threads(threads)


@functools.cache
def _probe_once() -> float:
    return probe_seconds()


def probe_factor(seconds: float | None = None) -> float:
    """This machine's time over the rates' machine's, from the probe (``seconds``: a probe's time,
    measured here when None; once per process)."""
    return (_probe_once() if seconds is None else seconds) / PROBE_REFERENCE_S


def store_factor(runs: list[dict], nominal: Callable[[dict], float | None]) -> tuple[float, int] | None:
    """(median of measured / nominal seconds, how many) over earlier ``runs`` (each a finished
    trial's params and its measured seconds: ``{"params": ..., "seconds": ...}``); ``nominal(params)``
    is what the rates say for one (None: not comparable). None below ``MIN_TRIALS`` comparable runs."""
    ratios = []
    for run in runs:
        expected = nominal(run["params"])
        if expected and expected > 0 and run["seconds"] > 0:
            ratios.append(run["seconds"] / expected)
    return (statistics.median(ratios), len(ratios)) if len(ratios) >= MIN_TRIALS else None


def finished_trials(tracking_uri: str, experiment: str, limit: int = 200) -> list[dict]:
    """The last ``limit`` finished trials of ``experiment`` in the store at ``tracking_uri``: their
    params (values as logged: strings) and measured seconds (their MLflow run's span)."""
    from mlflow.tracking import MlflowClient

    from sweeps.objective import WALL_TIME_S

    client = MlflowClient(tracking_uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        return []
    runs = client.search_runs([exp.experiment_id], filter_string="attributes.status = 'FINISHED'",
                              max_results=limit, order_by=["attributes.end_time DESC"])
    # The run's own span, start to end: the training, its checkpoints and artifacts, what the plan's
    # estimate covers beyond Ray's start-up (the trainable's own time, wall_time_s, leaves them out),
    # less its evaluation blocks (eval_time_s): the plan estimates those on their own.
    return [{"params": dict(r.data.params),
             "seconds": (r.info.end_time - r.info.start_time) / 1000.0 - r.data.metrics.get("eval_time_s", 0.0)}
            for r in runs if WALL_TIME_S in r.data.metrics and "mlflow.parentRunId" in r.data.tags
            and r.info.end_time and r.info.start_time]


@dataclasses.dataclass(frozen=True)
class Calibration:
    """This machine's time over the rates' for a trial of each algorithm (``per_algo``, from the
    store) or of any (``factor``), and where it came from, in words."""

    factor: float
    source: str
    per_algo: dict = dataclasses.field(default_factory=dict)

    def __call__(self, algo: str) -> float:
        return self.per_algo.get(algo, self.factor)


def machine_factor(tracking_uri: str, experiment: str, nominal: Callable[[dict], float | None]) -> Calibration:
    """The plan's calibration (module docstring). From the store, an algorithm with ``MIN_TRIALS``
    earlier trials of its own gets its own factor (the rates of some algorithms are further off
    than others'), the others the factor over all of them."""
    allowed = mode()
    if allowed == "off":
        return Calibration(1.0, f"the rates as measured ({ENV}=off)")
    if allowed in ("auto", "store"):
        try:
            runs = finished_trials(tracking_uri, experiment)
        except Exception:  # an unreadable store is not the plan's business: the probe answers
            runs = []
        found = store_factor(runs, nominal)
        if found:
            factor, n = found
            per_algo = {}
            for algo in {r["params"].get("algo") for r in runs} - {None}:
                own = store_factor([r for r in runs if r["params"].get("algo") == algo], nominal)
                if own:
                    per_algo[algo] = own[0]
            return Calibration(factor, f"{n} earlier trials in this store ran at {factor:.2f}x the rates"
                               + (f" ({', '.join(f'{a} {f:.2f}x' for a, f in sorted(per_algo.items()))})"
                                  if per_algo else ""), per_algo)
        if allowed == "store":
            return Calibration(1.0, f"the rates as measured (fewer than {MIN_TRIALS} earlier trials in this store)")
    seconds = _probe_once()
    return Calibration(probe_factor(seconds),
                       f"a {seconds:.2f} s probe here against {PROBE_REFERENCE_S:.2f} s where the rates hold")
