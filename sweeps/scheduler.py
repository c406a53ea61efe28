"""Early stopping per configuration: ASHA deciding on a configuration's seeds together (issue 36).

Each seed of a configuration is its own Tune trial (one MLflow run each). Tune's ASHA decides per
trial, so it could stop one seed of a configuration and keep another, and a configuration would be
reported on a mix of full and truncated seeds; Ray's docs advise against its Repeater with early
stopping for that reason. :class:`ConfigurationASHA` is asynchronous successive halving
(Li et al. 2020, Tune's ``AsyncHyperBandScheduler`` with one bracket) over configurations:

- rungs at ``grace_period · rf^k`` env steps below the budget (rf = ``reduction_factor``, 4 as
  Tune's); nothing is stopped before the first, and the plan derives it from the multiplier's own
  warm-up (:func:`grace_period`);
- a seed reaching a rung records its objective there (its first result at or past the rung: the
  seeds' iterations are the same size, so these are equal env steps) and, while a sibling seed has
  not reached it, is paused (Tune checkpoints it and frees its CPUs) so that it cannot run on to the
  end alone;
- when the last live seed arrives, the configuration's mean is compared with the rung's cutoff over
  the configurations recorded there before it (ASHA's: the 1 − 1/rf quantile); below it every seed
  stops, paused or running, else every seed goes on. A decision is final: a seed that reaches the
  rung later (a duplicate of the configuration proposed again by the searcher) gets it too. A seed
  that fails for good no longer counts as awaited.

Its state is not restored by ``--resume`` (Tune's schedulers are not): decisions already made stand
in MLflow, the rungs of a resumed sweep fill again from the results that follow.
"""

from __future__ import annotations

import math

import numpy as np
from ray.tune.experiment import Trial
from ray.tune.schedulers import FIFOScheduler, TrialScheduler

from sweeps import spaces

#: ASHA's reduction factor (Tune's default): the top 1/rf of the configurations at a rung go on.
REDUCTION_FACTOR = 4


def configuration_key(config: dict) -> str:
    """A Tune trial's configuration without its seed (spaces.config_id, the MLflow ``lac.config_id``)."""
    spec = spaces.trial_spec(config)
    return spaces.config_id(spec.task, int(spec.timesteps or 0), dict(spec.params or spec.overrides))


def milestones(grace_period: int, max_t: int, reduction_factor: float = REDUCTION_FACTOR) -> list[int]:
    """The rungs: ``grace_period · rf^k`` env steps, ascending, below ``max_t``."""
    out, m = [], float(grace_period)
    while m < max_t:
        out.append(int(math.ceil(m)))
        m *= reduction_factor
    return out


class ConfigurationASHA(FIFOScheduler):
    """The module docstring. ``seeds``: the seeds each configuration runs with (a configuration is
    decided once this many of its trials reached a rung, fewer if some failed)."""

    def __init__(self, *, time_attr: str, metric: str, mode: str, max_t: int, grace_period: int, seeds: int,
                 reduction_factor: float = REDUCTION_FACTOR):
        super().__init__()
        if mode not in ("max", "min"):
            raise ValueError(f"mode {mode!r}; accepted: max | min")
        self.time_attr, self._metric, self._mode = time_attr, metric, mode  # Tune's properties read these
        self.sign = 1.0 if mode == "max" else -1.0
        self.max_t, self.grace_period, self.seeds, self.rf = max_t, grace_period, seeds, reduction_factor
        self.rungs = milestones(grace_period, max_t, reduction_factor)
        self.key: dict[str, str] = {}  # trial id → its configuration
        self.values: dict[tuple[str, int], dict[str, float]] = {}  # (configuration, rung) → trial id → value
        self.recorded: dict[int, dict[str, float]] = {m: {} for m in self.rungs}  # rung → configuration → mean
        self.decisions: dict[tuple[str, int], str] = {}
        self.failed: dict[str, set[str]] = {}
        self.waiting: dict[str, Trial] = {}  # paused at a rung until its siblings arrive
        self.num_stopped = 0

    def _key(self, trial: Trial) -> str:
        if trial.trial_id not in self.key:
            self.key[trial.trial_id] = configuration_key(trial.config)
        return self.key[trial.trial_id]

    def on_trial_add(self, tune_controller, trial: Trial) -> None:
        self._key(trial)

    def on_trial_result(self, tune_controller, trial: Trial, result: dict) -> str:
        if self.time_attr not in result or self._metric not in result:
            return TrialScheduler.CONTINUE
        key, t = self._key(trial), result[self.time_attr]
        for rung in self.rungs:
            if t < rung:
                break
            values = self.values.setdefault((key, rung), {})
            if trial.trial_id in values:
                continue
            value = float(result[self._metric])
            values[trial.trial_id] = self.sign * value if math.isfinite(value) else -math.inf
            decision = self._decide(tune_controller, key, rung)
            if decision is None:  # a sibling has not reached this rung yet: wait for it
                self.waiting[trial.trial_id] = trial
                return TrialScheduler.PAUSE
            if decision == TrialScheduler.STOP:
                self.num_stopped += 1
                return TrialScheduler.STOP
        return TrialScheduler.CONTINUE

    def _decide(self, tune_controller, key: str, rung: int) -> str | None:
        """The configuration's decision at ``rung`` (made once its live seeds are all there; None
        before), applied to its seeds waiting there."""
        if (key, rung) in self.decisions:
            return self.decisions[key, rung]
        values = self.values.get((key, rung), {})
        awaited = max(1, self.seeds - len(self.failed.get(key, ())))
        if len(values) < awaited:
            return None
        mean = float(np.mean(list(values.values())))
        earlier = self.recorded[rung]
        cutoff = np.nanpercentile(list(earlier.values()), (1 - 1 / self.rf) * 100) if earlier else None
        decision = TrialScheduler.STOP if cutoff is not None and mean < cutoff else TrialScheduler.CONTINUE
        earlier[key] = mean
        self.decisions[key, rung] = decision
        for trial_id in [i for i in self.waiting if i in values]:
            trial = self.waiting.pop(trial_id)
            if decision == TrialScheduler.STOP:  # paused: stopped where it waits
                self.num_stopped += 1
                tune_controller.stop_trial(trial)
        return decision

    def on_trial_complete(self, tune_controller, trial: Trial, result: dict) -> None:
        """A seed that ended (its budget reached in a step past a rung it had not reported at):
        its value counts at those rungs, so that its siblings waiting there are decided."""
        if not result or self.time_attr not in result or self._metric not in result:
            return
        key, value = self._key(trial), float(result[self._metric])
        for rung in [r for r in self.rungs if r <= result[self.time_attr]]:
            values = self.values.setdefault((key, rung), {})
            if trial.trial_id not in values:
                values[trial.trial_id] = self.sign * value if math.isfinite(value) else -math.inf
                self._decide(tune_controller, key, rung)

    def on_trial_error(self, tune_controller, trial: Trial) -> None:
        """A seed failed for good: its siblings no longer wait for it."""
        key = self._key(trial)
        self.failed.setdefault(key, set()).add(trial.trial_id)
        self.waiting.pop(trial.trial_id, None)
        for rung in self.rungs:
            values = self.values.get((key, rung), {})
            values.pop(trial.trial_id, None)
            if any(i in values for i in self.waiting):
                self._decide(tune_controller, key, rung)

    def choose_trial_to_run(self, tune_controller) -> Trial | None:
        """FIFO's choice, never a seed waiting for its siblings at a rung."""
        trials = [t for t in tune_controller.get_trials() if t.trial_id not in self.waiting]
        for status in (Trial.PENDING, Trial.PAUSED):
            for trial in trials:
                if trial.status == status:
                    return trial
        return None

    def debug_string(self) -> str:
        cuts = ", ".join(f"{m:,}: {len(r)} configurations" for m, r in self.recorded.items())
        return f"ConfigurationASHA: {self.num_stopped} seeds stopped; rungs {cuts}"


def grace_period(trials, timesteps: int, override: int | None = None) -> tuple[int, str]:
    """(env steps, why): the first rung. ``override`` (the sweep file's ``grace_period``) when
    given; else a quarter of the budget (Tune's ASHA example) or, if longer, the longest warm-up of
    the multipliers in ``trials`` (registry ``warmup_env_steps``: the env steps before the
    constraint's multiplier can act on the policy), so that no configuration is judged before its
    multiplier had a chance to pull its cost down."""
    from lac_rllib.algorithms.registry import warmup_env_steps

    if override is not None:
        return int(override), "the sweep file's grace_period"
    quarter = max(1, timesteps // 4)
    warmups = {(t.algo, warmup_env_steps(t.algo, t.params or {})) for t in trials}
    longest = max(warmups, key=lambda w: w[1], default=(None, 0))
    if longest[1] > quarter:
        return min(longest[1], timesteps), f"{longest[0]}'s multiplier warm-up ({longest[1]:,} env steps)"
    return quarter, "a quarter of the budget (every multiplier's warm-up is shorter)"
