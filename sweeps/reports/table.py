"""The paper's tables from a sweep: tasks × algorithms, each cell beside the published figures.

A sweep over several algorithms (``--space table1``, ``table2``, ``compare``, or any sweep whose
trials run two or more ``algo``) gets, in its parent run's ``summary/``, a table in the layout of
the paper's Tables 1 and 2: a block of rows per task, a column per algorithm (``table.md``,
``table.html`` with the intervals on hover, ``table.png``).

Conventions:
- A cell is one (task, algorithm): the final return and cost of its trials, mean ± std over seeds
  (ddof=1) and the 95% interval of the mean (sweeps/reports/verdicts.py). Failed trials and trials
  a scheduler stopped early are counted, not averaged (as in summary.md).
- **Bold**: a feasible cell by the one rule (sweeps/reports/verdicts.py: ≥ 80% of its seeds within the
  trials' ``cost_limit``); the paper bolds by mean cost, which two seeds far over and one at 0 can meet.
- ★: the best feasible algorithm of the task, the highest mean return among its feasible cells
  (the paper's blue); ties at the printed precision (2 decimals) are all marked.
- Below the cells, the same algorithm on the same task as published (sweeps/reports/published.yaml): the
  paper's figure (Table 1 or 2) and, on Safety-Gymnasium's tasks, OmniSafe's; blank where a source
  has none. Each at the sweep's own budget where the source has a figure there (OmniSafe's at 500k,
  1M and 2.5M are read from its published curves: "read from a curve", ± the reading's tolerance,
  not a std), else its final one at the source's env steps, said beside it.
- The table states the sweep's budget (env steps per trial) and, when it is not the published
  figures' budget, says so: a quick-budget table is a machinery check, not the paper's result.
- No table (None, ""): fewer than two algorithms in the trials (an ablation, a search), or an
  algorithm that ran more than one configuration on a task (a cell would average different
  configurations; summary.md keeps them apart).

The published figures are data, checked when read (sweeps/reports/published.py).
"""

from __future__ import annotations

import dataclasses
import html
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lac_rllib.algorithms.registry import DEFAULT_ALGO  # noqa: E402
from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, EPISODE_RETURN  # noqa: E402
from sweeps.reports.configurations import fmt_num, is_na, prepared  # noqa: E402
from sweeps.reports.published import ROWS, AtSteps, Beside, Published, Shown, Source, published  # noqa: E402
from sweeps.reports.verdicts import CONFIDENCE, METHODS, configuration_feasible, mean_interval, seeds_line  # noqa: E402
from sweeps.score import described  # noqa: E402

BEST_MARK = "★"
BEST_COLOUR = "#1f4fd1"  # the paper's blue


# ----------------------------------------------------------------------------- the table


@dataclasses.dataclass(frozen=True)
class Cell:
    """One algorithm on one task: its seeds' final return and cost."""

    n_seeds: int  #: finished trials (those averaged)
    n_failed: int  #: failed trials and trials stopped early (counted, not averaged)
    ret: tuple[float, float, float, float]  #: mean, std, 95% interval low, high
    cost: tuple[float, float, float, float]
    cost_limit: float
    feasible: bool = False  #: mean cost ≤ the limit
    best: bool = False  #: the task's highest feasible mean return (ties kept)


@dataclasses.dataclass(frozen=True)
class Table:
    """Tasks (rows) × algorithms (columns); ``cells[(task, algo)]``, absent where one did not run."""

    tasks: tuple[str, ...]
    algos: tuple[str, ...]
    cells: dict
    limits: dict  #: task → its limit (the trials' median)
    published: Published
    scores: tuple = ()  #: the score each counted trial was ranked on (sweeps/score.py)

    def name(self, algo: str) -> str:
        """The column's name: the paper's for its algorithms, else ours (a user's module path)."""
        return self.published.algorithms.get(algo, algo)

    def figures_beside(self, budget_steps: int) -> Beside:
        """The published figures of its tasks and algorithms beside its runs of ``budget_steps`` env
        steps, resolved once for all that writes the table."""
        return self.published.beside(self.tasks, self.algos, budget_steps)


def _one_configuration_each(df: pd.DataFrame) -> bool:
    """Whether every (task, algorithm) ran one configuration (its seeds), by every column that names
    one (a search's samples share their group and differ in ``config``)."""
    keys = [k for k in ("group", "param", "value", "config", "config_id") if k in df]
    if not keys:
        return True
    configs = df[keys].map(str).agg("|".join, axis=1)
    return bool((configs.groupby([df["task"].astype(str), df["algo"].astype(str)]).nunique() <= 1).all())


def _stats(x: pd.Series) -> tuple[float, float, float, float]:
    mean, lo, hi = mean_interval(x)
    return mean, float(x.std(ddof=1)), lo, hi  # the std is NaN with one seed


def _column_order(algos: list[str], names: list[str]) -> list[str]:
    """The published file's order (the paper's columns, LAC last); another algorithm (a user's
    module) before LAC, by name."""
    last = names.index(DEFAULT_ALGO) - 0.5 if DEFAULT_ALGO in names else len(names)
    return sorted(algos, key=lambda a: (names.index(a) if a in names else last, a))


def build_table(trials: pd.DataFrame, pub: Published | None = None) -> Table | None:
    """The table of ``trials`` (one row per trial, with ``task`` and ``algo``), or None where the
    sweep is not one over algorithms (the module docstring)."""
    if trials is None or trials.empty or "algo" not in trials or trials["algo"].astype(str).nunique() < 2:
        return None
    df, failed = prepared(trials)
    if COST_LIMIT not in df:
        df[COST_LIMIT] = math.nan
    if not _one_configuration_each(df):
        return None
    pub = pub or published()
    left_out = failed | df["status"].astype(str).eq("STOPPED")
    order = pub.task_order()
    tasks = sorted(dict.fromkeys(df["task"].astype(str)),
                   key=lambda t: (order.index(t) if t in order else len(order), t))
    algos = _column_order(list(dict.fromkeys(df["algo"].astype(str))), list(pub.algorithms))
    cells, limits = {}, {}
    for task in tasks:
        at = df["task"].astype(str) == task
        limits[task] = float(pd.to_numeric(df.loc[at, COST_LIMIT], errors="coerce").median())
        for algo in algos:
            rows = at & (df["algo"].astype(str) == algo)
            if not rows.any():
                continue
            ok = df[rows & ~left_out]
            ret, cost = (pd.to_numeric(ok[c], errors="coerce") for c in (EPISODE_RETURN, EPISODE_COST))
            limit = pd.to_numeric(df.loc[rows, COST_LIMIT], errors="coerce").median()
            limit = limits[task] if is_na(limit) else float(limit)
            c = Cell(len(ok), int((rows & left_out).sum()), _stats(ret), _stats(cost), limit)
            cells[(task, algo)] = dataclasses.replace(c, feasible=configuration_feasible(cost[ret.notna()], limit))
    for task in tasks:
        feasible = {a: c for (t, a), c in cells.items() if t == task and c.feasible and not is_na(c.ret[0])}
        if feasible:
            top = round(max(c.ret[0] for c in feasible.values()), 2)
            for a, c in feasible.items():
                cells[(task, a)] = dataclasses.replace(c, best=round(c.ret[0], 2) == top)
    scores = tuple(df.loc[~left_out, "score"]) if "score" in df else ()
    return Table(tuple(tasks), tuple(algos), cells, limits, pub, scores)


# ----------------------------------------------------------------------------- how it is written


def _pm(mean_std) -> str:
    mean, std = mean_std[0], mean_std[1]
    return "–" if is_na(mean) else f"{fmt_num(mean)} ± {fmt_num(std)}"


def steps_text(n: int) -> str:
    """Env steps as the papers write them: 2.5M, 10M, 40k."""
    for unit, size in (("M", 1_000_000), ("k", 1_000)):
        if n >= size:
            return f"{n / size:g}{unit}"
    return str(n)


def budget_caption(beside: Beside, budget_note: str = "") -> str:
    """What the table's runs had (``beside.steps``) and what the published figures beside them had:
    a table at another budget never reads as the paper's."""
    budget_steps = beside.steps
    text = f"Budget: {budget_steps:,} env steps per trial" + (f" ({budget_note})" if budget_note else "")
    steps, read = {}, []
    for (row, _, _), s in beside.figures.items():
        steps.setdefault(row, set()).add(s.steps)
        if s.reading is not None and row not in read:
            read.append(row)
    if not steps:
        return text + "."
    theirs = "; ".join(f"{ROWS[r]}'s at {' and '.join(steps_text(s) for s in sorted(v))}"
                       for r, v in steps.items())
    if read:  # some figures are at this budget, read from a source's curves
        lead = f"{text}, the paper's" if steps.get("paper") == {budget_steps} else text
        elsewhere = any(s.steps != budget_steps and s.reading is None for s in beside.figures.values())
        who = " and ".join(f"{ROWS[r]}'s" for r in read)
        return (f"{lead}. The published figures beside the cells: {theirs} env steps; {who} at this budget are "
                "read from its published curves (± the reading's tolerance, not a std)"
                + ("; one at another budget is a reference, not a result at this one." if elsewhere else "."))
    if steps.get("paper") == {budget_steps}:
        return f"{text}, the paper's. The published figures beside the cells: {theirs} env steps."
    return (f"{text}, not the published figures' ({theirs} env steps): they are beside the cells as a reference, "
            "not as results at this budget.")


def _ours(cell: Cell | None, which: str, intervals: bool = True) -> str:
    """A cell's return (``which="ret"``) or cost as the markdown prints it."""
    if cell is None:
        return ""
    if not cell.n_seeds:
        return f"failed ({cell.n_failed})" if which == "ret" else ""
    mean, std, lo, hi = getattr(cell, which)
    text = _pm((mean, std))
    text = f"**{text}**" if cell.feasible else text
    if which == "ret" and cell.best:
        text += f" {BEST_MARK}"
    if intervals:
        text += f" [{fmt_num(lo)}, {fmt_num(hi)}]" if not is_na(lo) else " [–]"
    if which == "ret" and cell.n_failed:
        text += f" ({cell.n_seeds} seeds; {cell.n_failed} failed or stopped)"
    return text


def _published_rows(table: Table, task: str, beside: Beside) -> list[tuple[str, list[Shown | None], bool]]:
    """(row label, the figure shown per algorithm or None, whether each cell names its steps) for
    each source row with a figure on ``task``; a label names the steps when its figures share them
    (those of what stands beside the runs: :attr:`Shown.steps`)."""
    rows = []
    for key, label in ROWS.items():
        shown = [beside.figures.get((key, task, a)) for a in table.algos]
        steps = {s.steps for s in shown if s is not None}
        if steps:
            one = len(steps) == 1
            rows.append((f"{label} ({steps_text(next(iter(steps)))})" if one else label, shown, not one))
    return rows


def _figure_text(s: Shown | None, with_steps: bool) -> str:
    """A figure as a cell: beside a run, its reading at the run's budget where it has one."""
    if s is None:
        return ""
    f, r = s.figure, s.reading
    if r is not None:
        return f"{reading_text(r)} ({steps_text(r.steps) + ', ' if with_steps else ''}read from a curve)"
    return f"{_pm(f.return_)} / {_pm(f.cost)}" + (f" ({steps_text(f.steps)})" if with_steps else "")


def reading_text(r: AtSteps) -> str:
    """A reading off a curve, return / cost, each ± the reading's tolerance as written: ``16.2 ±1 / 59 ±2``."""
    cost = "–" if r.cost is None else f"{r.cost:g} ±{r.tolerance.cost:g}"
    return f"{r.return_:g} ±{r.tolerance.return_:g} / {cost}"


def _value(s: Shown, which: str) -> float:
    """The mean return (``which="ret"``) or cost of a figure beside a run (NaN: not read)."""
    f, r = s.figure, s.reading
    if r is not None:
        v = r.return_ if which == "ret" else r.cost
        return math.nan if v is None else v
    return (f.return_ if which == "ret" else f.cost)[0]


def legend_line(intervals: bool = True) -> str:
    what = (f"Mean ± std over seeds [{CONFIDENCE:.0%} interval of the mean: {METHODS['mean']}]" if intervals else
            f"Mean ± std over seeds (the {CONFIDENCE:.0%} intervals: summary/table.md)")
    return (f"{what}; **bold**: feasible (≥ 80% of the seeds within the limit); {BEST_MARK}: the task's best "
            "feasible return (ties kept). Below each task: the same algorithm as published, return / cost "
            "(blank: none published).")


def _sources(table: Table, beside: Beside) -> tuple[list[Source], list[str]]:
    """The sources of the figures shown, and the figures' own notes (once per algorithm and note),
    then, per source, the curves the figures beside the runs were read from."""
    shown = [s.figure for s in beside.figures.values()]
    notes = dict.fromkeys((f.algo, ROWS[table.published.sources[f.source].row], f.note) for f in shown if f.note)
    curves = {}  # source -> (the readings' steps, the images' URLs)
    for s in beside.figures.values():
        if s.reading is not None:
            f = s.figure
            steps, urls = curves.setdefault(f.source, ({}, {}))  # dicts: ordered, each once
            steps[s.reading.steps] = None
            urls[table.published.sources[f.source].curves[f.curve]] = None
    read = [f"{ROWS[table.published.sources[k].row]} at {' and '.join(steps_text(n) for n in steps)}: read from a "
            f"curve, the height of its mean curve in {', '.join(f'[{Path(url).name}]({url})' for url in urls)} (± "
            'the reading\'s tolerance, not a std; docs/sweeps.md, "Figures read from a curve")'
            for k, (steps, urls) in curves.items()]
    return ([table.published.sources[k] for k in dict.fromkeys(f.source for f in shown)],
            [f"{table.name(algo)} ({col}): {note}" for algo, col, note in notes] + read)


def _source_text(s: Source) -> str:
    return (f"{s.simulator}; {s.steps:,} env steps" + (f"; {s.seeds}" if s.seeds else "")
            + (f". {s.note}" if s.note else ""))


def sources_lines(table: Table, beside: Beside) -> list[str]:
    """The sources of the figures shown as markdown list items, then the figures' own notes and the
    curves the figures beside the runs were read from."""
    sources, notes = _sources(table, beside)
    return ([f"- {ROWS[s.row]}: [{s.title}]({s.url}); {_source_text(s)}" for s in sources]
            + [f"- {note}" for note in notes])


def markdown(table: Table, beside: Beside, budget_note: str = "", intervals: bool = True,
             sources: bool = True) -> str:
    """The table as markdown (``table.md``, the note): its budget, a block of rows per task (our
    return and cost, then each source's figures, ``beside``: :meth:`Table.figures_beside`), the legend, the
    seeds and the sources."""
    def row(*cells) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    lines = [f"**Final return and cost per task and algorithm.** {budget_caption(beside, budget_note)}",
             "", row("task (limit)", "", *(table.name(a) for a in table.algos)),
             "|---|---|" + "---:|" * len(table.algos)]
    for task in table.tasks:
        cells = [table.cells.get((task, a)) for a in table.algos]
        lines.append(row(f"`{task}` ({_limit_text(table.limits[task])})", "return",
                         *(_ours(c, "ret", intervals) for c in cells)))
        lines.append(row("", "cost", *(_ours(c, "cost", intervals) for c in cells)))
        lines += [row("", label, *(_figure_text(s, each) for s in shown))
                  for label, shown, each in _published_rows(table, task, beside)]
    counts = [c.n_seeds for c in table.cells.values() if c.n_seeds]
    lines += ["", legend_line(intervals), "", f"Scores: {described(table.scores)}. {seeds_line(counts)}"]
    if sources and beside.figures:
        lines += ["", "Published figures:", *sources_lines(table, beside)]
    return "\n".join(lines) + "\n"


def _limit_text(limit: float) -> str:
    return "no limit" if is_na(limit) else f"limit {limit:g}"


def table_markdown(trials: pd.DataFrame, budget_steps: int, budget_note: str = "", limit: int | None = None) -> str:
    """The table of ``trials`` as markdown for the parent run's note, "" when the sweep has none
    (the module docstring). With ``limit`` (characters), the intervals, then the sources' lines are
    left out (they stay in summary/table.md) until it fits; what still does not is cut."""
    table = build_table(trials)
    return "" if table is None else note_markdown(table, table.figures_beside(budget_steps), budget_note, limit)


def note_markdown(table: Table, beside: Beside, budget_note: str = "", limit: int | None = None) -> str:
    """:func:`table_markdown` of a table built already, its figures resolved already."""
    text = ""
    for intervals, sources in ((True, True), (False, True), (False, False)):
        text = markdown(table, beside, budget_note, intervals, sources)
        if limit is None or len(text) <= limit:
            return text
    kept = text[:limit - 40].rpartition("\n")[0]  # whole lines
    return kept + "\n… (the rest: summary/table.md)\n"


# ----------------------------------------------------------------------------- table.html, table.png


HTML_STYLE = """
body { font-family: sans-serif; font-size: 13px; margin: 16px; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; white-space: nowrap; }
th { background: #f3f3f3; }
td.task { text-align: left; font-family: monospace; }
td.what { text-align: left; color: #555; }
td.pub { color: #777; font-size: 12px; }
tr.first td { border-top: 2px solid #888; }
.best { color: %s; }
caption { caption-side: top; text-align: left; padding: 6px 0; max-width: 1200px; white-space: normal; }
""" % BEST_COLOUR


def _html_ours(cell: Cell | None, which: str) -> str:
    """A cell's return or cost with its interval and seeds on hover (``title``)."""
    if cell is None:
        return "<td></td>"
    if not cell.n_seeds:
        return f"<td>failed ({cell.n_failed})</td>" if which == "ret" else "<td></td>"
    mean, std, lo, hi = getattr(cell, which)
    ci = f"[{fmt_num(lo)}, {fmt_num(hi)}]" if not is_na(lo) else "[–] (one seed)"
    what = "return" if which == "ret" else "cost"
    hover = f"{what} mean {fmt_num(mean)}, {CONFIDENCE:.0%} interval {ci}; {cell.n_seeds} seeds" + (
        f", +{cell.n_failed} failed or stopped" if cell.n_failed else "")
    text = html.escape(_pm((mean, std)))
    text = f"<b>{text}</b>" if cell.feasible else text
    if which == "ret" and cell.best:
        text = f'<span class="best">{text} {BEST_MARK}</span>'
    return f'<td title="{html.escape(hover)}">{text}</td>'


def _html_figure(table: Table, shown: Shown | None, with_steps: bool) -> str:
    if shown is None:
        return '<td class="pub"></td>'
    f, r = shown.figure, shown.reading
    s = table.published.sources[f.source]
    at = (f"{f.steps:,} env steps" if r is None else
          f"{r.steps:,} env steps, read from its curve {s.curves[f.curve]} (± the reading's tolerance, not a std)"
          + (f"; {r.note}" if r.note else ""))
    hover = (f"{s.title}: {s.tasks[f.task].name}, {at}, limit {f.cost_limit:g}, {s.simulator}"
             + (f". {f.note}" if f.note else ""))
    return f'<td class="pub" title="{html.escape(hover)}">{html.escape(_figure_text(shown, with_steps))}</td>'


def table_html(table: Table, beside: Beside, path, budget_note: str = "") -> str:
    """The table as a standalone HTML page: the intervals, seeds and sources on hover."""
    caption = (f"<b>Final return and cost per task and algorithm.</b> "
               f"{html.escape(budget_caption(beside, budget_note))}<br>"
               f"{html.escape(legend_line()).replace('**bold**', '<b>bold</b>')} Hover a cell for its interval "
               "and seeds, a published figure for its source.")
    head = "".join(f"<th>{html.escape(table.name(a))}</th>" for a in table.algos)
    rows = [f"<tr><th>task (limit)</th><th></th>{head}</tr>"]
    for task in table.tasks:
        cells = [table.cells.get((task, a)) for a in table.algos]
        rows.append(f'<tr class="first"><td class="task">{html.escape(task)} ({_limit_text(table.limits[task])})</td>'
                    f'<td class="what">return</td>{"".join(_html_ours(c, "ret") for c in cells)}</tr>')
        rows.append(f'<tr><td></td><td class="what">cost</td>{"".join(_html_ours(c, "cost") for c in cells)}</tr>')
        rows += [f'<tr><td></td><td class="what">{html.escape(label)}</td>'
                 f'{"".join(_html_figure(table, s, each) for s in shown)}</tr>'
                 for label, shown, each in _published_rows(table, task, beside)]
    found, notes = _sources(table, beside)
    sources = "".join([f'<li>{ROWS[s.row]}: <a href="{html.escape(s.url)}">{html.escape(s.title)}</a>; '
                       f"{html.escape(_source_text(s))}</li>" for s in found]
                      + [f"<li>{html.escape(note)}</li>" for note in notes])
    body = (f"<table><caption>{caption}</caption>{''.join(rows)}</table>"
            + (f"<p>Published figures:</p><ul>{sources}</ul>" if sources else ""))
    Path(path).write_text(f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>The table</title>'
                          f"<style>{HTML_STYLE}</style></head><body>{body}</body></html>\n", encoding="utf-8")
    return str(path)


#: How each row of published figures is drawn in table.png: (marker, colour).
MARKERS = {"paper": ("D", "tab:orange"), "omnisafe": ("X", "tab:purple")}


def table_png(table: Table, beside: Beside, path, budget_note: str = "") -> str:
    """The table as a figure: a row of panels per task (final return, final cost), a bar per
    algorithm with its interval, feasible ones dark, the best blue, infeasible ones grey; the
    published figures as markers, the limit dashed."""
    import textwrap

    k = len(table.algos)
    fig, axes = plt.subplots(len(table.tasks), 2, figsize=(13, (0.42 * k + 1.3) * len(table.tasks) + 1.1),
                             squeeze=False)
    y = np.arange(k)[::-1]  # the first algorithm at the top, as the table's first column
    for (ax_r, ax_c), task in zip(axes, table.tasks):
        cells = [table.cells.get((task, a)) for a in table.algos]
        for ax, which in ((ax_r, "ret"), (ax_c, "cost")):
            for yi, algo, cell in zip(y, table.algos, cells):
                _bar(ax, yi, cell, which)
                for key, (marker, colour) in MARKERS.items():
                    shown = beside.figures.get((key, task, algo))
                    if shown is not None:
                        ax.plot(_value(shown, which), yi, marker, color=colour, ms=6, mew=1)
            ax.axvline(0, color="black", lw=0.5)
            ax.set_yticks(y, [_tick(table, a, c) for a, c in zip(table.algos, cells)], fontsize=9)
            for tick, cell in zip(ax.get_yticklabels(), cells):
                tick.set_fontweight("bold" if cell is not None and cell.feasible else "normal")
        if not is_na(table.limits[task]):
            ax_c.axvline(table.limits[task], ls="--", color="tab:red")
        ax_r.set_title(f"{task}: final return", fontsize=10)
        ax_c.set_title(f"{task}: final cost ({_limit_text(table.limits[task])})", fontsize=10)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in (BEST_COLOUR, "#4a4a4a", "#c8c8c8")]
    labels = [f"best feasible ({BEST_MARK})", "feasible (bold)", "over the limit"]
    for key, (marker, colour) in MARKERS.items():
        handles.append(plt.Line2D([], [], ls="", marker=marker, color=colour))
        labels.append(f"{ROWS[key]} (published)")
    handles.append(plt.Line2D([], [], ls="--", color="tab:red"))
    labels.append("cost limit")
    fig.legend(handles, labels, loc="upper center", ncol=len(labels), fontsize=9, bbox_to_anchor=(0.5, 1.0),
               frameon=False)
    caption = budget_caption(beside, budget_note)
    height = fig.get_figheight()  # the legend and the caption take the top 0.8 inches
    fig.text(0.5, 1 - 0.32 / height, "\n".join(textwrap.wrap(
        f"Mean over seeds with its {CONFIDENCE:.0%} interval. {caption}", 150)), ha="center", va="top", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.8 / height))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def _bar(ax, yi: float, cell: Cell | None, which: str) -> None:
    if cell is None or not cell.n_seeds or is_na(getattr(cell, which)[0]):
        return
    mean, _, lo, hi = getattr(cell, which)
    colour = BEST_COLOUR if cell.best else "#4a4a4a" if cell.feasible else "#c8c8c8"
    ax.barh(yi, mean, height=0.6, color=colour)
    if not (is_na(lo) or is_na(hi)):
        ax.errorbar(mean, yi, xerr=[[mean - lo], [hi - mean]], color="black", capsize=3, lw=1)


def _tick(table: Table, algo: str, cell: Cell | None) -> str:
    name = table.name(algo)
    if cell is None:
        return f"{name} (not run)"
    if not cell.n_seeds:
        return f"{name} (failed)"
    return f"{name} {BEST_MARK}" if cell.best else name


def write_table_report(trials: pd.DataFrame, out_dir, budget_steps: int, budget_note: str = "",
                       note_limit: int | None = None) -> tuple[dict[str, str], str] | None:
    """Write table.md, table.html and table.png of ``trials`` into ``out_dir``; ({file name: path},
    the table as the parent run's note shows it, within ``note_limit`` characters: :func:`table_markdown`),
    or None when the sweep has no table (the module docstring). ``budget_steps``: the sweep's env
    steps per trial; ``budget_note``: what else the budget means (a quick budget's small networks).
    The table is built and its published figures resolved once for all of them."""
    table = build_table(trials)
    if table is None:
        return None
    beside = table.figures_beside(budget_steps)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(markdown(table, beside, budget_note), encoding="utf-8")
    return ({"table.md": str(out / "table.md"),
             "table.html": table_html(table, beside, out / "table.html", budget_note),
             "table.png": table_png(table, beside, out / "table.png", budget_note)},
            note_markdown(table, beside, budget_note, note_limit))
