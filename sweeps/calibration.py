"""How fast this machine runs trials, for the plan's estimate (sweeps/run.py ``estimate_trial_s``).

The plan's rates (``RATE``, each algorithm's ``plan_update_s``) were measured on one machine; a
trial on another runs faster or slower by a factor that depends on its CPU (AVX2 or AVX512 torch
kernels, clock, cache). The plan multiplies its estimate by that factor, taken, in this order, from:

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
from typing import Callable

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
