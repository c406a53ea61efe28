"""The published figures a table is read beside (sweeps/reports/published.yaml): the paper's Tables 1-2 and
OmniSafe's benchmark on our simulator, as data checked when read.

Each figure has a source (with its URL, simulator, env steps and per-task limit), our task id and
algorithm name, and [mean, std] of return and cost as the source prints them. A figure may also
carry ``at_steps``: the same curve at earlier budgets, read off the source's published learning-curve
image with a stated tolerance (:class:`AtSteps`), so a run at 500k is set beside the source at 500k
rather than at its final 1e7 (:meth:`Figure.at`; a table's at once: :meth:`Published.beside`). Whether a
run is "within" such a band is decided in one place, :func:`band_verdict` (its docstring states the
rule; the docs' within/overlaps/below/above are its words). A bad file is one line,
``FILE:LINE: key.path: what is wrong`` (:class:`PublishedError`). sweeps/reports/table.py and
benchmarks/fidelity.py place them beside their runs.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from sweeps.bounded_yaml import YamlRefused
from sweeps.bounded_yaml import read as read_yaml
from sweeps.bounded_yaml import read_text as read_yaml_text
from sweeps.sweep_file import MAX_BUDGET, Int, KeyedError, Origin, Real, SafeName

PUBLISHED_FILE = Path(__file__).with_name("published.yaml")
#: A run is at a reading's steps when its budget is within this fraction of them: a reading is the
#: curve's height over +-3 pixel columns (+-49k env steps on a 1e7-step figure), no sharper than that.
AT_STEPS_SLACK = 0.05
#: The rows of published figures under each task (a source's ``row``) and their labels, in print order.
ROWS = {"paper": "paper", "omnisafe": "OmniSafe"}


class PublishedError(ValueError):
    """A bad published-figures file: ``FILE:LINE: key.path: what is wrong`` (one line)."""


def _schema() -> ConfigDict:
    return ConfigDict(extra="forbid", use_attribute_docstrings=True, populate_by_name=True)


Std = Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)]
Text = Annotated[str, Field(min_length=1, max_length=400)]


class SourceTask(BaseModel):
    """A task as a source names it, and the limit its figures are under."""

    model_config = _schema()
    name: Text
    """The source's name of the task (the paper's "PointGoal", "Ant-v3")."""
    cost_limit: Real = Field(ge=0)
    """The limit of the source's runs on it (as printed)."""


class Source(BaseModel):
    """Where figures were published: one table of one paper or benchmark."""

    model_config = _schema()
    title: Text
    """The table, e.g. "OmniSafe's on-policy benchmark on Safety-Gymnasium, Table 2"."""
    url: str = Field(pattern=r"^https://\S+$", max_length=400)
    """Where to read it (a repository at a commit where there is one)."""
    row: Literal["paper", "omnisafe"]
    """Which row under each task its figures print in (:data:`ROWS`)."""
    simulator: Text
    """What its runs ran on: a figure only compares with a run on the same."""
    steps: Int(1, MAX_BUDGET)
    """Env steps per run behind its figures (a figure may say another)."""
    seeds: Text | None = None
    """How many runs its figures average, as it says."""
    note: Annotated[str, Field(min_length=1, max_length=1000)] | None = None
    """What else a reader must know to compare with it."""
    tasks: dict[str, SourceTask] = Field(min_length=1)
    """Our task id → the source's name of it and its limit."""
    curves: dict[SafeName, Annotated[str, Field(pattern=r"^https://\S+$", max_length=400)]] = {}
    """The source's published learning-curve images that its figures' ``at_steps`` were read from:
    a short id → the image's URL at a commit."""


class Tolerance(BaseModel):
    """How far a reading off a curve image may be from the curve's value: ± in the figure's units."""

    model_config = _schema()
    return_: Std = Field(alias="return")
    """± of the return read."""
    cost: Std | None = None
    """± of the cost read (absent where the cost is not readable)."""


class AtSteps(BaseModel):
    """The figure's algorithm on its task at an earlier budget: the height of the source's published
    mean curve at ``steps`` env steps, read off the image (pixel positions of the gridlines and of the
    curve's own colour; docs/sweeps.md, "Figures read from a curve"). A curve's height is a mean
    over seeds as the source smooths and plots it, not its table's statistic: the ± is the reading's
    tolerance, not a std."""

    model_config = _schema()
    steps: Int(1, MAX_BUDGET)
    """Env steps at which the curve was read (fewer than the figure's own)."""
    return_: Real = Field(alias="return")
    """The mean return curve's height there."""
    cost: Real | None = None
    """The mean cost curve's height there; absent where the figure does not show it (``note`` says why)."""
    read_from_figure: Literal[True]
    """Always true: an intermediate figure a source prints in a table is a figure of its own (a
    source or a figure ``steps``), so everything here was read off a curve."""
    tolerance: Tolerance
    """± of the reading."""
    note: Text | None = None
    """What limits the reading (a curve off the axis, hidden by another)."""

    @model_validator(mode="after")
    def _cost_or_why(self):
        if self.cost is None and self.note is None:
            raise KeyedError(("note",), "a reading without a cost must say why (note)")
        if (self.cost is None) != (self.tolerance.cost is None):
            raise KeyedError(("tolerance", "cost"), "a cost read needs its tolerance, and only a cost read has one")
        return self


class Figure(BaseModel):
    """One algorithm on one task as a source prints it; ``steps`` and ``cost_limit`` default to the
    source's (filled in when the file is read)."""

    model_config = _schema()
    source: SafeName
    """A key of ``sources``."""
    task: Text
    """Our task id (docs/tasks.md), a key of its source's ``tasks``."""
    algo: Text
    """Our algorithm's name, a key of ``algorithms``."""
    return_: tuple[Real, Std] = Field(alias="return")
    """[mean, std] of the final return."""
    cost: tuple[Real, Std]
    """[mean, std] of the final cost."""
    steps: Int(1, MAX_BUDGET) | None = None
    """Env steps behind this figure (default: its source's)."""
    cost_limit: Real | None = Field(None, ge=0)
    """The limit of its runs (default: its source's for the task)."""
    note: Text | None = None
    """What differs for this figure (e.g. the algorithm's own limit)."""
    curve: SafeName | None = None
    """The image ``at_steps`` were read from: a key of its source's ``curves``."""
    at_steps: tuple[AtSteps, ...] = ()
    """The same curve at earlier budgets, read off ``curve`` (ascending steps)."""

    def at(self, steps: int | None) -> AtSteps | None:
        """The reading beside a run of ``steps`` env steps (within :data:`AT_STEPS_SLACK` of its
        steps), None where there is none: the figure beside such a run is the final one."""
        if steps is None:
            return None
        return next((r for r in self.at_steps if abs(steps - r.steps) <= AT_STEPS_SLACK * r.steps), None)

    def steps_at(self, steps: int | None) -> int:
        """The env steps of what stands beside a run of ``steps``: a reading's, else the figure's."""
        r = self.at(steps)
        return r.steps if r else self.steps


class Published(BaseModel):
    """The published-figures file (sweeps/reports/published.yaml)."""

    model_config = _schema()
    algorithms: dict[str, Text] = Field(min_length=1)
    """Our algorithm names → the names the table prints (the paper's columns), in the table's order."""
    sources: dict[SafeName, Source] = Field(min_length=1)
    """The sources by a short id."""
    figures: tuple[Figure, ...] = Field(min_length=1)
    """The figures."""

    @model_validator(mode="after")
    def _resolve(self):
        seen, filled = set(), []
        for i, f in enumerate(self.figures):
            if f.source not in self.sources:
                raise KeyedError(("figures", i, "source"), f"{f.source!r} is not a source; accepted: "
                                                           f"{', '.join(self.sources)}")
            src = self.sources[f.source]
            if f.task not in src.tasks:
                raise KeyedError(("figures", i, "task"), f"{f.task!r} is not a task of {f.source}; accepted: "
                                                         f"{', '.join(src.tasks)}")
            if f.algo not in self.algorithms:
                raise KeyedError(("figures", i, "algo"), f"{f.algo!r} is not in algorithms; accepted: "
                                                         f"{', '.join(self.algorithms)}")
            _check_readings(f, src, i)
            if (f.source, f.task, f.algo) in seen:
                raise KeyedError(("figures", i), f"a second figure of {f.algo} on {f.task} from {f.source}")
            seen.add((f.source, f.task, f.algo))
            filled.append(f.model_copy(update={"steps": f.steps or src.steps,
                                               "cost_limit": src.tasks[f.task].cost_limit
                                               if f.cost_limit is None else f.cost_limit}))
        self.figures = tuple(filled)
        return self

    def find(self, row: str, task: str, algo: str) -> Figure | None:
        """The first figure of ``algo`` on ``task`` among the sources printed in ``row``."""
        return next((f for f in self.figures if f.task == task and f.algo == algo
                     and self.sources[f.source].row == row), None)

    def task_order(self) -> list[str]:
        """Our task ids in the order the sources list them (the papers' row order)."""
        return list(dict.fromkeys(t for s in self.sources.values() for t in s.tasks))

    def beside(self, tasks, algos, steps: int) -> Beside:
        """The figures of ``algos`` on ``tasks`` in each source row, as they stand beside runs of
        ``steps`` env steps: each with its reading there where it has one (:meth:`Figure.at`)."""
        found = ((row, t, a, self.find(row, t, a)) for row in ROWS for t in tasks for a in algos)
        return Beside(steps, {(row, t, a): Shown(f, f.at(steps)) for row, t, a, f in found if f is not None})


@dataclasses.dataclass(frozen=True)
class Shown:
    """A figure beside a run: the figure, and its reading at the run's budget (None: the figure's own,
    final one stands there)."""

    figure: Figure
    reading: AtSteps | None

    @property
    def steps(self) -> int:
        """The env steps of what stands beside the run: the reading's, else the figure's."""
        return self.reading.steps if self.reading else self.figure.steps


@dataclasses.dataclass(frozen=True)
class Beside:
    """The published figures beside a table's runs of ``steps`` env steps (:meth:`Published.beside`)."""

    steps: int
    """The runs' env steps."""
    figures: dict[tuple[str, str, str], Shown]
    """(source row, task, algo) → the figure shown there, in print order (rows, tasks, algos)."""


@dataclasses.dataclass(frozen=True)
class BandVerdict:
    """Where a run's seeds stand against a reference band (:func:`band_verdict`)."""

    word: Literal["within", "overlaps", "outside"]
    """``within``: the seeds' mean lies in the band; ``overlaps``: it does not, but mean ± 1 SD
    reaches the band; ``outside``: not even mean ± 1 SD reaches it."""
    side: Literal["below", "above"] | None
    """Where the mean lies when it is not within (None when it is)."""
    mean: float
    """The mean of the seeds' scores."""
    sd: float
    """Their sample standard deviation (ddof = 1; 0 for one seed)."""
    delta: float
    """mean − the band's centre."""

    @property
    def phrase(self) -> str:
        """How a report says it: ``within``, ``overlaps, mean below`` (``… above``), ``below``, ``above``."""
        if self.word == "within":
            return "within"
        return f"overlaps, mean {self.side}" if self.word == "overlaps" else self.side


def band_verdict(scores, centre: float, tolerance: float) -> BandVerdict:
    """Whether a run is **within the reference band**: the one rule every report and doc uses.

    The band is [centre − tolerance, centre + tolerance], closed: for a figure read off a curve
    (:class:`AtSteps`), the curve's height ± the reading's tolerance; ``scores`` are the run's
    per-seed scores (one number per seed). The rule, on their mean m and sample SD s (ddof = 1, 0
    for one seed):

    - **within**: m lies in the band;
    - **overlaps** (said "overlaps, mean below/above"): m lies outside it but [m − s, m + s]
      reaches it; a statement about the seeds' spread, not about where the run's mean is, and a
      loose one: a run whose seeds scatter widely overlaps almost any band;
    - **outside** (said "below"/"above"): not even [m − s, m + s] reaches it.

    Neither word is a test: a curve reading's tolerance is how well the image can be read, not the
    source's spread over its seeds, so "outside" does not say the two differ beyond their noise,
    and "within" does not say they agree within it.
    """
    values = [float(x) for x in scores]
    if not values:
        raise ValueError("band_verdict needs at least one seed's score")
    if tolerance < 0:
        raise ValueError(f"a band's tolerance is ≥ 0, not {tolerance}")
    n = len(values)
    mean = sum(values) / n
    sd = (sum((x - mean) ** 2 for x in values) / (n - 1)) ** 0.5 if n > 1 else 0.0
    lo, hi = centre - tolerance, centre + tolerance
    delta = mean - centre
    if lo <= mean <= hi:
        return BandVerdict("within", None, mean, sd, delta)
    side = "below" if mean < lo else "above"
    word = "overlaps" if mean - sd <= hi and mean + sd >= lo else "outside"
    return BandVerdict(word, side, mean, sd, delta)


def _check_readings(f: Figure, src: Source, i: int) -> None:
    """A figure's readings: off a named image of its source, before its own steps, each budget once."""
    if f.curve is not None and f.curve not in src.curves:
        raise KeyedError(("figures", i, "curve"), f"{f.curve!r} is not a curve of {f.source}; accepted: "
                                                  f"{', '.join(src.curves) or 'none (the source has no curves)'}")
    if f.at_steps and f.curve is None:
        raise KeyedError(("figures", i, "curve"), "at_steps are read off a curve: name it (a key of the source's "
                                                  "curves)")
    final = f.steps or src.steps
    steps = [r.steps for r in f.at_steps]
    for j, n in enumerate(steps):
        if n >= final:
            raise KeyedError(("figures", i, "at_steps", j, "steps"),
                             f"{n:,} is not before the figure's own {final:,} env steps (the figure is that)")
        if j and n <= steps[j - 1]:
            raise KeyedError(("figures", i, "at_steps", j, "steps"), "at_steps go in ascending steps, each once")


def load_published(path: str | Path = PUBLISHED_FILE, text: str | None = None) -> Published:
    """The published figures at ``path``, checked; a PublishedError names the line and the key."""
    path = Path(path)
    try:
        data, node = read_yaml(read_yaml_text(path) if text is None else text, yaml.SafeLoader)
    except YamlRefused as e:
        raise PublishedError(f"{path}{f':{e.line}' if e.line else ''}: {e.message}") from None
    try:
        return Published.model_validate(data)
    except ValidationError as e:
        raise PublishedError(_first_error(e, Origin(path, node))) from None


def _first_error(e: ValidationError, origin: Origin) -> str:
    err = e.errors()[0]
    loc = tuple(err["loc"])
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, KeyedError):
        loc = (*loc, *cause.loc)
    msg = err["msg"].removeprefix("Value error, ")
    if err["type"] == "extra_forbidden":
        msg = f"unknown key {loc[-1]!r}"
    return f"{origin(loc)}: {msg}"


@functools.lru_cache(maxsize=1)
def published() -> Published:
    """The package's published figures (sweeps/reports/published.yaml), read once."""
    return load_published()
