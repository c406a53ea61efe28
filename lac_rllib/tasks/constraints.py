"""The constraints a task declares: each a name and the ``info`` keys its per-step cost is read from.

A safety specification often has several parts (stay off hazards, do not knock vases), and
Safety-Gymnasium already reports each part's cost apart in ``info`` (``cost_hazards``,
``cost_vases_contact``, ...) beside their sum, ``info["cost"]``, the one number every algorithm
trains on by default (``cost_limit``). A run that sets ``constraints: {hazards: 10, vases: 5}``
reads each constraint's cost instead and holds each under its own limit.

A constraint's step cost is the sum of its keys' values; for an ``indicator`` constraint, 1 where
that sum is > 0, else 0: Safety-Gymnasium's ``constrain_indicator`` convention (builder.py
``_cost``), which already makes each key an indicator and ``info["cost"]`` the indicator of any
violation. So ``vases`` (touched or moving) costs 1 on a step where either happens, as
``info["cost"]`` would for the vases alone.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class Constraint:
    """One part of a task's safety specification."""

    #: Its name in sweep files (``constraints: {NAME: limit}``), metrics and reports.
    name: str
    #: The ``info`` keys whose values sum to its step cost.
    keys: tuple[str, ...]
    #: 1[sum of the keys > 0] instead of the sum (Safety-Gymnasium's indicator costs).
    indicator: bool = False

    def step_cost(self, info: dict) -> float:
        """This constraint's cost of one step, from the step's ``info``."""
        total = 0.0
        for key in self.keys:
            try:
                total += float(info[key])
            except (KeyError, TypeError):
                keys = sorted(map(str, info)) if isinstance(info, dict) else "none: not a dict"
                raise KeyError(f"constraint {self.name!r}: the env's step info has no {key!r} "
                               f"(keys: {keys})") from None
        return float(total > 0.0) if self.indicator else total


def as_constraints(data) -> tuple[Constraint, ...]:
    """Constraints from their plain form (a TaskSpec that travelled as data: dicts or lists)."""
    out = []
    for c in data or ():
        if isinstance(c, Constraint):
            out.append(c)
        elif isinstance(c, dict):
            out.append(Constraint(c["name"], tuple(c["keys"]), bool(c.get("indicator", False))))
        else:
            name, keys, *rest = c
            out.append(Constraint(name, tuple(keys), bool(rest[0]) if rest else False))
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class ConstraintSet:
    """A run's constraints with their limits, in the task's order (``SafeTaskConfig.constraint_set``):
    the one place a step's cost vector and an episode's cost vector are read."""

    constraints: tuple[Constraint, ...]
    limits: tuple[float, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.constraints)

    def __len__(self) -> int:
        return len(self.constraints)

    def step_costs(self, info: dict) -> np.ndarray:
        """(K,) float32: each constraint's cost of one step."""
        return np.array([c.step_cost(info) for c in self.constraints], dtype=np.float32)

    def as_data(self) -> dict:
        """Plain data (RLlib records a connector's constructor arguments; Tune trial configs)."""
        return {"constraints": [dataclasses.asdict(c) for c in self.constraints], "limits": list(self.limits)}

    @classmethod
    def from_data(cls, data: dict) -> ConstraintSet:
        return cls(as_constraints(data["constraints"]), tuple(float(b) for b in data["limits"]))


def select(declared: tuple[Constraint, ...], limits: dict, *, task_id: str) -> ConstraintSet:
    """The task's constraints named in ``limits`` (name → b), in the task's order; a name the task
    does not declare, or a limit that is not a finite number >= 0, is a ValueError naming it and
    what is accepted."""
    names = [c.name for c in declared]
    if not limits:
        raise ValueError(f"constraints: an empty mapping; accepted: a limit per constraint of {task_id} "
                         f"({', '.join(names) or 'it declares none'})")
    for name, b in limits.items():
        if name not in names:
            accepted = ", ".join(names) if names else "none: it declares no constraints (its cost is info['cost'])"
            raise ValueError(f"constraints: {task_id} has no constraint {name!r}; accepted: {accepted}")
        if isinstance(b, bool) or not isinstance(b, (int, float)) or not math.isfinite(b) or b < 0:
            raise ValueError(f"constraints: the limit of {name!r} is {b!r}; accepted: a finite number >= 0")
    chosen = tuple(c for c in declared if c.name in limits)
    return ConstraintSet(chosen, tuple(float(limits[c.name]) for c in chosen))
