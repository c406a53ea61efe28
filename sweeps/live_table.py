"""The sweep's live table: one row per trial that says what the trial is, and a progress line.

A Tune ``ProgressReporter`` (Tune calls ``should_report``/``report``). Tune's default output
names a trial by its config, which for a grid of nested dicts prints as ``...iteration': None}``;
here a trial is its label (algorithm, group, swept value, seed: ``TrialSpec.label``), and the table holds
what a safe-RL user watches: status, iteration, env steps, return, cost, feasible, ν. With several
constraints the cost is the worst one's (the largest excess over its limit: ``lane 11.0/10``) and
feasible the joint rule. The last line counts trials done / total and estimates the time left from
the finished trials.
"""

from __future__ import annotations

import math
import sys
import time

from ray.tune import ProgressReporter
from ray.tune.result import TIME_TOTAL_S, TRAINING_ITERATION

from lac_rllib.constrained.metrics import COST_LIMIT, ENV_STEPS, EPISODE_COST, EPISODE_RETURN, FEASIBLE, NU

COLUMNS = ("trial", "status", "iter", "env steps", "return", "cost", "feasible", "ν")
_DONE = ("TERMINATED", "ERROR")


def _cell(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    return format(value, fmt)


def format_table(rows: list[list[str]]) -> str:
    """Text columns (trial, status) left-aligned, figures right-aligned, two spaces apart."""
    widths = [max(len(str(x)) for x in col) for col in zip(COLUMNS, *rows)]
    def line(cells):
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))).rstrip()
    return "\n".join([line(COLUMNS), *(line(r) for r in rows)])


def cost_cell(r: dict) -> str:
    """The cost column: the episode cost, or with several constraints the worst one's, ``NAME cost/limit``."""
    prefix = f"{COST_LIMIT}/"
    limits = {k[len(prefix):]: v for k, v in r.items() if k.startswith(prefix)}
    costs = {n: r.get(f"{EPISODE_COST}/{n}") for n in limits}
    known = {n: c for n, c in costs.items() if c is not None and c == c}
    if len(limits) < 2 or not known:
        return _cell(r.get(EPISODE_COST), ".1f")
    worst = max(known, key=lambda n: known[n] - limits[n])
    return f"{worst} {known[worst]:.1f}/{limits[worst]:g}"


def trial_row(trial) -> list[str]:
    r = trial.last_result or {}
    feasible = r.get(FEASIBLE)
    return [str(trial), trial.status, _cell(r.get(TRAINING_ITERATION), "d"), _cell(r.get(ENV_STEPS), ",.0f"),
            _cell(r.get(EPISODE_RETURN), ".2f"), cost_cell(r),
            "–" if feasible is None or feasible != feasible else ("yes" if feasible else "no"),
            _cell(r.get(NU), ".3f")]


def progress_line(trials, total: int, concurrency: int, now: float | None = None) -> str:
    """``trials done/total (failed) · running · ETA`` from the mean wall time of finished trials."""
    done = [t for t in trials if t.status in _DONE]
    failed = sum(t.status == "ERROR" for t in trials)
    running = [t for t in trials if t.status == "RUNNING"]
    durations = [t.last_result[TIME_TOTAL_S] for t in done
                 if t.status == "TERMINATED" and (t.last_result or {}).get(TIME_TOTAL_S)]
    line = f"progress: {len(done)}/{total} trials done" + (f" ({failed} failed)" if failed else "")
    line += f" · {len(running)} running"
    if not durations:
        return line + " · ETA after the first trial finishes"
    mean = sum(durations) / len(durations)
    # Time still owed: whole trials not started, and the rest of the running ones (at least 0).
    left = (total - len(done) - len(running)) * mean
    left += sum(max(mean - (t.last_result or {}).get(TIME_TOTAL_S, 0.0), 0.0) for t in running)
    eta = left / max(1, concurrency)
    return line + f" · ETA ~{eta / 60:.0f} min (mean {mean / 60:.1f} min per finished trial, n={len(durations)})"


class LiveTable(ProgressReporter):
    """Prints the table every ``every`` seconds and when the sweep ends."""

    def __init__(self, total: int, concurrency: int, every: float = 30.0, max_rows: int = 20):
        # Tune pickles the reporter with its state (resume): no stream kept, stdout looked up per print.
        self.total, self.concurrency, self.every, self.max_rows = total, concurrency, every, max_rows
        self._last = 0.0

    def should_report(self, trials, done: bool = False) -> bool:
        if done or time.time() - self._last >= self.every:
            self._last = time.time()
            return True
        return False

    def render(self, trials, done: bool) -> str:
        # Running trials first (what is happening), then the latest finished, then pending.
        order = {"RUNNING": 0, "TERMINATED": 1, "ERROR": 1, "PAUSED": 2, "PENDING": 3}
        shown = sorted(trials, key=lambda t: order.get(t.status, 4))
        hidden = 0 if done else max(0, len(shown) - self.max_rows)
        rows = [trial_row(t) for t in shown[: len(shown) - hidden]]
        lines = [format_table(rows)]
        if hidden:
            lines.append(f"… {hidden} more trials not shown")
        lines.append(progress_line(trials, self.total, self.concurrency))
        return "\n".join(lines)

    def report(self, trials, done: bool, *sys_info: str) -> None:
        print(self.render(trials, done) + "\n", file=sys.stdout, flush=True)
