"""A sweep's plan: what will run, where it goes and what it costs, fixed before Ray starts.

``sweeps/run.py`` makes it from the command line (every input checked), prints it, and hands it
whole to ``sweeps/sweep.py``; ``sweep.json`` records it so that ``--resume`` can compare.
"""

from __future__ import annotations

import dataclasses

from sweeps.spaces import TrialSpec


@dataclasses.dataclass(frozen=True)
class Plan:
    space: str
    task: str | None  #: None: every paper task (the ``paper`` space)
    budget: str
    timesteps: int  #: env steps per trial
    trials: list[TrialSpec] | None  #: the grid's trials; None for ``search`` (Optuna samples them)
    n_trials: int
    concurrency: int  #: trials at once
    sets: dict  #: the user's --set FIELD=VALUE, in every trial
    estimated_wall_s: float
    estimated_cpu_h: float
    tracking_uri: str
    experiment: str
    name: str  #: the sweep's name: its Tune directory under ``storage`` and its MLflow parent run
    storage: str
    optuna_storage: str | None  #: the search space's Optuna storage URL

    def record(self) -> dict:
        """The plan as JSON-ready data (``sweep.json``, the parent run's plan.json): the trials by label."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "trials"}
        return out | {"trial_labels": [t.label() for t in self.trials] if self.trials else None}
