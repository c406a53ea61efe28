"""An algorithm's search space: the fields worth tuning, each with its range, scale and source.

Declared on the config class (``SEARCH_SPACE``), as the fields are, so a sweep file's
``search: default`` (sweeps/sweep_file.py) and a tuned comparison (``tune:``, sweeps/tuned.py) search
every algorithm over its own important fields, not LAC's alone. A range is absolute (``low, high``)
or relative to the field's default on the trial's task (``around=k``: [default / k, default · k] on a
log scale), since defaults span orders of magnitude across presets (SAC-Lag's actor lr is 3e-4 on
MuJoCo and 5e-6 on Safety-Gym) and a search that excludes the default cannot say whether tuning helped.
Plain data: no Ray, no sweeps import (imports go one way).
"""

from __future__ import annotations

import dataclasses

KINDS = ("int", "uniform", "loguniform", "choice")


@dataclasses.dataclass(frozen=True)
class Searched:
    """One searched field: ``kind`` over ``args`` (int/uniform/loguniform: low, high; choice: the
    values), or ``around`` its default (loguniform over [default / around, default · around]), and
    ``source``: why this field and this range (a reference's sensitivity study, the paper's grid,
    the evidence here)."""

    kind: str
    source: str
    args: tuple = ()
    around: float | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"search kind {self.kind!r}; accepted: {' | '.join(KINDS)}")
        if (self.around is None) == (not self.args):
            raise ValueError("give args or around (one of them)")
        if self.around is not None and (self.kind != "loguniform" or self.around <= 1):
            raise ValueError(f"around {self.around}: accepted: a factor > 1 of a loguniform range")

    def bounds(self, default) -> tuple:
        """The distribution's arguments for a task whose default of this field is ``default``."""
        if self.around is None:
            return tuple(self.args)
        if not isinstance(default, (int, float)) or default <= 0:
            raise ValueError(f"a range around the default needs a positive default, got {default!r}")
        return (float(default) / self.around, float(default) * self.around)


def lr(source: str, around: float = 10.0) -> Searched:
    """A learning rate: log-uniform over a decade either side of the task's default."""
    return Searched("loguniform", source, around=around)


#: Why a multiplier's learning rate is searched (every Lagrangian algorithm's).
MULTIPLIER_LR = ("Spoor et al. 2026 (arXiv 2510.17564): the multiplier's learning rate decides how it "
                 "behaves, and it differs across limits and tasks")
#: Why the policy's learning rate is searched (the on-policy family's).
POLICY_LR = "Andrychowicz et al. 2021 (What matters in on-policy RL): the learning rate matters most"
