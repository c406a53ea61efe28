"""A sweep's plan: what will run, where it goes and what it costs, fixed before Ray starts.

``sweeps/run.py`` makes it in one pass (file and flags → the resolved sweep → its trials → the
estimate), prints it, and hands it whole to ``sweeps/sweep.py``, which reads nothing else;
``sweep.yaml`` and ``sweep.json`` record it so that ``--resume`` can compare.
"""

from __future__ import annotations

import dataclasses

from sweeps.spaces import TrialSpec
from sweeps.sweep_file import SweepFile


@dataclasses.dataclass(frozen=True)
class Infra:
    """Where a sweep runs and records (the command line's, not the sweep file's: they differ per machine)."""

    address: str | None  #: the Ray cluster; None: a local Ray
    address_from: str | None  #: "--address" or "RAY_ADDRESS" (what ``ray job submit`` sets)
    tracking_uri: str
    storage: str  #: as given (``Plan.storage`` is resolved)
    resume: bool
    max_failures: int
    optuna_seed: int
    optuna_storage: str | None = None  #: as given (None: beside the MLflow store)


@dataclasses.dataclass(frozen=True)
class Plan:
    sweep: SweepFile  #: the resolved sweep (defaults and flags applied): what every trial comes from
    infra: Infra
    space: str  #: the built-in space, or the sweep file's stem
    tasks: tuple[str, ...]  #: task ids (a user's env registered under its id)
    user_tasks: dict  #: id → a user env's TaskSpec as data (lac_rllib/tasks/user.py), for the trials
    trials: list[TrialSpec] | None  #: the grid's trials; None for a search (Optuna samples them)
    n_trials: int
    concurrency: int  #: trials at once
    sets: dict  #: the fields every trial sets (the sweep's ``set``, and its one algorithm)
    timesteps: int  #: env steps per trial (the largest, where tasks' budgets differ)
    estimated_wall_s: float
    estimated_cpu_h: float
    name: str  #: the sweep's name: its Tune directory under ``storage`` and its MLflow parent run
    storage: str
    optuna_storage: str | None  #: a search's Optuna storage URL
    #: ``--confirm-top``: (K, seeds, budget) of the confirmation that follows the sweep (sweeps/confirm.py)
    confirm: tuple | None = None
    #: A confirmation sweep's winners (sweeps/confirm.py ``winners``): its report says whether each held up.
    confirms: tuple | None = None
    #: A user's algorithm (its import path) → the folder its trials import it from (registry.module_dir).
    user_algos: dict = dataclasses.field(default_factory=dict)
    #: Each trial's estimated seconds (a search: the first configuration's, per trial): the wall
    #: time at another concurrency (a cluster's, known once connected) is made from them again.
    trial_seconds: tuple = ()
    #: The evaluation blocks' share of the estimated time (sweeps/run.py ``estimate_eval_s``).
    eval_share: float = 0.0
    #: ``scheduler: asha``: (grace period in env steps, why, the rungs) (sweeps/scheduler.py); else None.
    early_stopping: tuple | None = None
    #: (factor, what it came from): this machine's speed against the rates' (sweeps/calibration.py).
    calibration: tuple = (1.0, "the rates as measured")

    @property
    def task(self) -> str | None:
        """The sweep's one task (None when it runs several)."""
        return self.tasks[0] if len(self.tasks) == 1 else None

    @property
    def budget(self) -> str:
        return str(self.sweep.budget)

    @property
    def seeds(self) -> tuple[int, ...]:
        return self.sweep.seed_list()

    @property
    def experiment(self) -> str:
        return self.sweep.experiment

    @property
    def tracking_uri(self) -> str:
        return self.infra.tracking_uri

    @property
    def swept_algos(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(t.algo for t in self.trials)) if self.trials else ()

    def record(self) -> dict:
        """The plan as JSON-ready data (``sweep.json``, the parent run's plan.json): the trials by label."""
        skip = ("trials", "sweep", "infra", "confirms", "trial_seconds")
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        return out | {"tracking_uri": self.tracking_uri, "budget": self.budget, "seeds": list(self.seeds),
                      "trial_labels": [t.label() for t in self.trials] if self.trials else None}
