"""Population-based training that respects the constraint (``searcher: pbt``, docs/sweeps.md).

Tune's ``PopulationBasedTraining`` ranks members on one number (``_quantiles``) and perturbs
without bounds (ray-project/ray#5035). :class:`ConstrainedPBT` keeps Tune's exploit and explore
and changes what they decide on and where they may go:

- **Ranking by the one feasibility rule on a window.** Members are ranked on
  :data:`sweeps.objective.OBJECTIVE_WINDOW`, the objective of the means of their last ``window``
  iterations (sweeps/trainable.py): feasible members by return, every infeasible member below them
  by how far over the limit (Deb's rule; with several constraints the joint rule's
  max_k (J_k − b_k)). One noisy iteration does not decide an exploit.
- **Synchronous, per sub-population.** Members exploit together at their sub-population's
  interval (env steps), so a donor's checkpoint and its copy are at the same env steps and the
  population spends exactly members × budget env steps. With several ``intervals`` the population
  is split round-robin into sub-populations (MF-PBT, Doulazmi et al. 2025), each exploiting within
  itself at its own interval; at a slower one's exploit its best member migrates into the next
  faster one, replacing that one's worst where the migrant ranks higher. ``growth`` > 1 multiplies a
  sub-population's interval after each of its exploits (IPBT, Chebykin et al. 2025, grows it).
- **Bounds.** After Tune's explore (×0.8 / ×1.2, or a resample with ``resample_probability``) each
  changed field is clipped to its search range and an integer rounded (:func:`clip_to_bounds`).
- **Seeded.** Explore and the donor's draw use the scheduler's own ``random.Random``, not the
  process's.

The exploit itself is Tune's: the member is paused, its config set to the perturbed copy of the
donor's, its checkpoint to the donor's; on restart sweeps/trainable.py restores the donor's whole
algorithm into the member rebuilt with the new fields (weights, targets, every optimizer's state,
each multiplier and its rule's state, the observation filter, the replay buffer: ``store_replay_buffer``
is forced on) and sets the optimizers' learning rates again (lac_rllib/constrained/changeable.py).
Like Tune's schedulers, its state is not restored by ``--resume``: each member resumes from its own
last checkpoint with its current (perturbed) config, and the sub-populations' next exploit times
are taken again from their members' env steps.
"""

from __future__ import annotations

import contextlib
import math
import random

import numpy as np
from ray.tune.experiment import Trial
from ray.tune.schedulers import PopulationBasedTraining

#: The Tune config key of a member's index (its seed's among the sweep's; sweeps/spaces.py REPEAT_INDEX):
#: member i belongs to sub-population i mod S (0: the fastest interval).
MEMBER_KEY = "__trial_index__"
#: The Tune config key of the sampled fields a member runs (sweeps/spaces.py ``trial_spec``).
OVERRIDES = "overrides"
#: A member's record in each of its checkpoints and, at its end, in its MLflow run: its last rows
#: (the window), its schedule [[env steps, {field: value}], ...] and its parents [[env steps, member]].
MEMBER_FILE = "member.json"
#: The MLflow tag of a member's ancestry: the members its weights descend from and when each copy
#: was made (a copy replaces its ancestry with the donor's, then the copy).
PARENTS_TAG = "lac.pbt.parents"
#: The MLflow tag of every copy the member made, in order, [[env steps, donor], ...] (its own history).
COPIES_TAG = "lac.pbt.copies"
#: A member's changeable fields are logged each iteration as ``schedule/FIELD``: its schedule's curve.
SCHEDULE_PREFIX = "schedule/"


def fields_at(schedule: list, env_steps: int) -> dict:
    """The fields a schedule [(env steps, {field: value}), ...] sets from ``env_steps`` on: each
    entry at or before them, later entries over earlier ones."""
    out = {}
    for at, fields in schedule:
        if int(at) <= env_steps:
            out.update(fields)
    return out


def window_row(rows: list[dict]) -> dict:
    """The mean of each numeric key over ``rows`` (a member's last iterations' rows): the row the
    windowed objective is computed from (each constraint's cost averaged before the joint rule)."""
    keys = set().union(*rows) if rows else set()
    out = {}
    for k in keys:
        values = [r[k] for r in rows if isinstance(r.get(k), (int, float))]
        if values:
            out[k] = float(np.mean(values))
    return out


def subpopulations(members: int, intervals: tuple[int, ...]) -> list[int]:
    """Member i's sub-population: round-robin over ``intervals`` (sorted fastest first)."""
    return [i % len(intervals) for i in range(members)]


def clip_to_bounds(config: dict, bounds: dict[str, tuple]) -> dict:
    """``config`` with each of its ``overrides`` named in ``bounds`` (field → (kind, low, high) or
    ("choice", values)) clipped into its range, an ``int`` field rounded."""
    fields = dict(config.get(OVERRIDES) or {})
    for name, (kind, *args) in bounds.items():
        if name not in fields or kind == "choice":
            continue  # a choice moves along its list (Tune's shift) or is resampled from it: inside
        low, high = args
        value = min(max(fields[name], low), high)
        fields[name] = int(round(value)) if kind == "int" else float(value)
    return {**config, OVERRIDES: fields}


class ConstrainedPBT(PopulationBasedTraining):
    """The module docstring. ``intervals``: env steps between a sub-population's exploits (one per
    sub-population, fastest first); ``bounds``: :func:`clip_to_bounds`'s; ``mutations``: Tune's
    ``hyperparam_mutations`` of the ``overrides``; ``migrate``: MF-PBT's migration from slow to fast."""

    def __init__(self, *, time_attr: str, metric: str, mode: str, intervals: tuple[int, ...], mutations: dict,
                 bounds: dict, quantile_fraction: float = 0.25, resample_probability: float = 0.25,
                 growth: float = 1.0, migrate: bool = True, seed: int | None = None):
        super().__init__(time_attr=time_attr, metric=metric, mode=mode, perturbation_interval=min(intervals),
                         hyperparam_mutations={OVERRIDES: mutations}, quantile_fraction=quantile_fraction,
                         resample_probability=resample_probability,
                         custom_explore_fn=lambda c: clip_to_bounds(c, bounds), log_config=False, synch=True)
        self.intervals = [float(i) for i in intervals]
        self.next_sync = list(self.intervals)  # per sub-population: the env steps of its next exploit
        self.growth, self.migrate = float(growth), bool(migrate)
        self.rng = random.Random(seed)
        self.exploits = [0] * len(intervals)
        self.migrations = 0
        self._only: int | None = None  # the sub-population a call is about

    def subpop(self, trial: Trial) -> int:
        return subpopulations(int(trial.config.get(MEMBER_KEY, 0)) + 1, tuple(self.intervals))[-1]

    @contextlib.contextmanager
    def _own_random(self):
        """Tune's explore and donor draw read the module ``random``: run them on this scheduler's."""
        outer = random.getstate()
        random.setstate(self.rng.getstate())
        try:
            yield
        finally:
            self.rng.setstate(random.getstate())
            random.setstate(outer)

    def _quantiles(self):
        """Tune's, over the sub-population of the call (all members outside one)."""
        if self._only is None:
            return super()._quantiles()
        saved = self._trial_state
        self._trial_state = {t: s for t, s in saved.items() if self.subpop(t) == self._only}
        try:
            return super()._quantiles()
        finally:
            self._trial_state = saved

    def on_trial_result(self, tune_controller, trial: Trial, result: dict) -> str:
        """Tune's synchronous PBT run on ``trial``'s sub-population alone, at its own interval."""
        k = self.subpop(trial)
        self._perturbation_interval, self._next_perturbation_sync = self.intervals[k], self.next_sync[k]
        before = self.next_sync[k]
        self._only = k
        try:
            with self._own_random():
                decision = super().on_trial_result(_SubPopulation(tune_controller, self, k), trial, result)
        finally:
            self._only = None
        self.next_sync[k] = self._next_perturbation_sync
        if self.next_sync[k] != before:  # the sub-population exploited
            self.exploits[k] += 1
            if self.growth != 1.0:
                self.intervals[k] *= self.growth
                self.next_sync[k] = max(before + self.intervals[k], self.next_sync[k])
            if self.migrate and k > 0:
                with self._own_random():
                    self._migrate(tune_controller, k)
            # Tune's experiment state now, not at its next periodic save: a kill before it would
            # resume the copied members with their old fields and checkpoints, though their MLflow
            # runs already record the copy.
            tune_controller.checkpoint(force=True)
        return decision

    def _migrate(self, tune_controller, k: int) -> None:
        """MF-PBT's migration: sub-population ``k``'s best member copied into sub-population k − 1's
        worst (its donor's whole state, its fields perturbed as any exploit), where it ranks higher."""
        def ranked(j):
            return sorted((t for t, s in self._trial_state.items() if self.subpop(t) == j and s.last_score is not None
                           and not math.isnan(s.last_score) and not t.is_finished()),
                          key=lambda t: self._trial_state[t].last_score)

        slow, fast = ranked(k), ranked(k - 1)
        if not slow or not fast:
            return
        donor, target = slow[-1], fast[0]
        if self._trial_state[donor].last_score <= self._trial_state[target].last_score:
            return
        if not self._trial_state[donor].last_checkpoint:
            self._trial_state[donor].last_checkpoint = donor.checkpoint
        if not self._trial_state[donor].last_checkpoint:
            return
        self._exploit(tune_controller, target, donor)
        self.migrations += 1

    def choose_trial_to_run(self, tune_controller) -> Trial | None:
        """The paused or pending member furthest behind among those short of their sub-population's
        next exploit (Tune's synchronous choice, per sub-population)."""
        trials = tune_controller.get_trials()
        waiting = [t for t in trials if t.status in (Trial.PENDING, Trial.PAUSED)]
        running = {self.subpop(t) for t in trials if t.status == Trial.RUNNING}
        for k in {self.subpop(t) for t in waiting} - running:
            # Every member of a sub-population waits at or past its next exploit and none runs to
            # trigger it: after a resume (this state starts again, the members come back at their
            # checkpoints' env steps, the exploit there already made) Tune's synchronous rule would
            # wait forever. The next exploit time moves on by the interval.
            members = [t for t in waiting if self.subpop(t) == k]
            while all(self._trial_state[t].last_train_time >= self.next_sync[k] for t in members):
                self.next_sync[k] += self.intervals[k]
        candidates = [t for t in waiting if self._trial_state[t].last_train_time < self.next_sync[self.subpop(t)]]
        candidates.sort(key=lambda t: self._trial_state[t].last_train_time)
        return candidates[0] if candidates else None

    def debug_string(self) -> str:
        subs = ", ".join(f"every {i:,.0f} env steps: {n} exploits" for i, n in zip(self.intervals, self.exploits))
        return f"ConstrainedPBT: {subs}; {self.migrations} migrations"


class _SubPopulation:
    """The Tune controller as one sub-population's members see it: its trials alone, the rest
    of the controller as it is (Tune's synchronous PBT waits for, and ranks, the trials it lists)."""

    def __init__(self, controller, scheduler: ConstrainedPBT, k: int):
        self._controller, self._scheduler, self._k = controller, scheduler, k

    def get_trials(self):
        return [t for t in self._controller.get_trials() if self._scheduler.subpop(t) == self._k]

    def get_live_trials(self):
        return [t for t in self._controller.get_live_trials() if self._scheduler.subpop(t) == self._k]

    def __getattr__(self, name):
        return getattr(self._controller, name)


#: The column of a PBT sweep's trials read back with each member's schedule (JSON of member.json's).
SCHEDULE_COLUMN = "schedule"


def with_schedules(trials, client, parent_run_id: str):
    """A PBT sweep's ``trials`` (sweeps/reports/results.py) with each member's schedule (its
    ``member.json``: its ancestors' fields up to each copy, then its own) as JSON in
    :data:`SCHEDULE_COLUMN`: the data its winners are chosen from (committed with a tuned comparison's)."""
    import json

    from sweeps.tracking import PARENT_TAG, TRIAL_TAG

    exp = client.get_run(parent_run_id).info.experiment_id
    schedules = []
    for trial_id in trials["trial_id"]:
        found = client.search_runs([exp], max_results=1, filter_string=f"tags.`{TRIAL_TAG}` = '{trial_id}' and "
                                                                       f"tags.`{PARENT_TAG}` = '{parent_run_id}'")
        try:
            with open(client.download_artifacts(found[0].info.run_id, MEMBER_FILE)) as f:
                schedules.append(json.dumps(json.load(f)["schedule"]))
        except (IndexError, OSError, KeyError, ValueError):  # a member that never finished: no schedule
            schedules.append(None)
    return trials.assign(**{SCHEDULE_COLUMN: schedules})


def winners(trials, k: int, least_costly_fallback: bool = False) -> list[dict]:
    """A finished PBT sweep's ``k`` best members by the one feasibility rule on their scores
    (feasible members by return), each with the schedule it followed (``trials`` read back
    :func:`with_schedules`): what a confirmation replays on fresh seeds as a fixed schedule (a
    group's ``schedule``, sweeps/trainable.py). With ``least_costly_fallback`` and no feasible
    member, the least costly one, ``feasible`` False (a tuned comparison confirms every algorithm)."""
    import json

    from sweeps.objective import feasible

    rows = trials[trials[SCHEDULE_COLUMN].notna()] if SCHEDULE_COLUMN in trials else trials.iloc[:0]
    ok = [bool(feasible(c, b)) for c, b in zip(rows["episode_cost"], rows["cost_limit"])]
    chosen = rows[ok].sort_values("episode_return", ascending=False).head(k)
    if not len(chosen) and least_costly_fallback and len(rows):
        chosen = rows.assign(_excess=rows["episode_cost"] - rows["cost_limit"]).sort_values("_excess").head(1)
    out = []
    for r in chosen.to_dict("records"):
        schedule = json.loads(r[SCHEDULE_COLUMN])
        out.append({"group": f"pbt{len(out) + 1}", "config": r["config"], "fields": {},
                    "name": f"{r['config']}-s{r['seed']}'s schedule",
                    "schedule": [{"at": int(at), "set": fields} for at, fields in schedule],
                    "feasible": bool(feasible(r["episode_cost"], r["cost_limit"])),
                    "search": {"return_mean": float(r["episode_return"]), "return_mean_ci_low": None,
                               "return_mean_ci_high": None, "cost_mean": float(r["episode_cost"]),
                               "feasible_fraction": float(feasible(r["episode_cost"], r["cost_limit"])),
                               "n_seeds": 1}})
    return out


def lineage_figure(client, parent_run_id: str, path: str, fields: tuple[str, ...]) -> bool:
    """The population over env steps on one figure: each member's schedule of ``fields`` (one panel
    each, log scale where the values span a decade), its return and its cost against the limit,
    an exploit marked where a member copied another. False: no member has logged anything."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, EPISODE_RETURN
    from sweeps.tracking import PARENT_TAG

    exp = client.get_run(parent_run_id).info.experiment_id
    runs = client.search_runs([exp], filter_string=f"tags.`{PARENT_TAG}` = '{parent_run_id}'", max_results=1000)
    if not runs:
        return False
    keys = [*(f"{SCHEDULE_PREFIX}{f}" for f in fields), EPISODE_RETURN, EPISODE_COST]
    fig, axes = plt.subplots(len(keys), 1, figsize=(8, 2.2 * len(keys)), sharex=True, squeeze=False)
    limit = None
    for i, run in enumerate(sorted(runs, key=lambda r: r.data.tags.get("mlflow.runName", ""))):
        colour, name = f"C{i % 10}", run.data.tags.get("mlflow.runName", "").split("-")[-1]
        parents = json.loads(run.data.tags.get(PARENTS_TAG, "[]"))
        for ax, key in zip(axes[:, 0], keys):
            history = sorted((m.step, m.value) for m in client.get_metric_history(run.info.run_id, key))
            if history:  # a schedule's value at step x is the one its iteration ending at x ran
                ax.plot(*zip(*history), color=colour, lw=1, label=name,
                        drawstyle="steps-pre" if key.startswith(SCHEDULE_PREFIX) else "default")
            for at, _ in parents:
                ax.axvline(at, color=colour, lw=0.5, ls=":")
        limit = run.data.metrics.get(COST_LIMIT, limit)
    for ax, key in zip(axes[:, 0], keys):
        ax.set_ylabel(key.removeprefix(SCHEDULE_PREFIX), fontsize=8)
        lines = [v for line in ax.get_lines() for v in line.get_ydata()]
        if key.startswith(SCHEDULE_PREFIX) and lines and min(lines) > 0 and max(lines) / min(lines) > 10:
            ax.set_yscale("log")
    if limit is not None:
        axes[-1, 0].axhline(limit, color="k", ls="--", lw=1)
    axes[0, 0].legend(fontsize=6, ncol=4)
    axes[-1, 0].set_xlabel("env steps (dotted: a member copied another there)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True
