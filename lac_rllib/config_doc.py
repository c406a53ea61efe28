"""docs/config.md, generated from every algorithm's ``config.py`` so it cannot drift from the code.

Regenerate with ``python -m lac_rllib.config_doc > docs/config.md`` (tests/test_docs.py checks it).
Fields are grouped by the ``# --- group ---`` comments of each params class, in source order.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
import sys

from lac_rllib.algorithms.lac.config import LACParams
from lac_rllib.tasks import get_task, known_tasks

REGENERATE = "python -m lac_rllib.config_doc > docs/config.md"
_GROUP = re.compile(r"^\s*# --- (.+?) ---\s*$")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _code(value) -> str:
    return f"`{_cell(repr(value))}`"


def field_groups(params_cls=LACParams) -> list[tuple[str, list[str]]]:
    """[(group title, [field names])] in the order ``params_cls`` declares them, its own fields
    first, then those of its bases (for LAC: the fields every constrained algorithm has); a field
    declared again by a subclass is listed where the subclass declares it."""
    groups: list[tuple[str, list[str]]] = []
    seen: set[str] = set()  # a field a subclass declares again (its own default) is listed once, there
    for cls in [c for c in params_cls.__mro__ if dataclasses.is_dataclass(c)]:
        source = inspect.getsource(cls)
        # Line numbers (1-based, within ``source``) of the group comments, and each field's group.
        titles = {i: m.group(1) for i, line in enumerate(source.splitlines(), 1) if (m := _GROUP.match(line))}
        for node in ast.parse(source).body[0].body:
            if not isinstance(node, ast.AnnAssign) or node.target.id in seen:
                continue
            seen.add(node.target.id)
            above = [i for i in titles if i < node.lineno]
            title = titles[max(above)] if above else "Fields"
            if not groups or groups[-1][0] != title:
                groups.append((title, []))
            groups[-1][1].append(node.target.id)
    return groups


def _algo_section(algo: str, first: bool) -> list[str]:
    """One algorithm's fields (grouped) and its presets. The fields every constrained algorithm has
    (``SafeTaskParams``) are listed with the first algorithm only, unless another declares its own default."""
    from lac_rllib.algorithms.registry import DEFAULT_ALGO, algo_config
    from lac_rllib.constrained.task_config import SafeTaskParams

    mod = algo_config(algo)
    params, fields, presets = mod.PARAMS, mod.FIELDS, mod.PRESETS
    docs, defaults, cls = fields.docs(), fields.defaults, mod.__name__
    shared = {f.name for f in dataclasses.fields(SafeTaskParams)}
    out = ["", f"## {fields.what} (`algo={algo}`)", "",
           f"`{params.__name__}` in `{params.__module__.replace('.', '/')}.py`. Set a field with "
           f"`{cls}().training(name=value)`, `lac-train --algo {algo} --set name=value` or the sweep's "
           f"`--set name=value`"
           + (f" (with `--set algo={algo}` or `--space compare`)." if algo != DEFAULT_ALGO else ".")]
    if not first:
        out += ["Its task and observation-filter fields are those of every algorithm (first section)."]
    base = {f.name: f.default for f in dataclasses.fields(SafeTaskParams)}
    for title, names in field_groups(params):
        # A shared field is listed again where the algorithm declares another default (RESPO's filter).
        names = [n for n in names if first or n not in shared or defaults[n] != base[n]]
        if not names:
            continue
        out += ["", f"### {title[:1].upper()}{title[1:]}", "", "| field | default | accepted | meaning |",
                "|---|---|---|---|"]
        out += [f"| `{n}` | {_code(defaults[n])} | {_cell(fields.ranges[n].text)} | {_cell(docs.get(n, ''))} |"
                for n in names]
    touched = [n for n in defaults if any(n in p for p in presets.values())]
    family = mod.TASK_FAMILY_OVERRIDES
    family_text = "; ".join(f"{f} tasks: " + ", ".join(f"`{k}={v!r}`" for k, v in o.items()) for f, o in family.items())
    out += [
        "", f"### {fields.what} presets", "",
        f"`{cls}().task(id)` applies the task's preset (`PRESETS` in `{mod.__name__.replace('.', '/')}.py`)"
        + (f", then its overrides per task family (the Tasks table's family: {family_text})" if family else "")
        + "; explicit `training(...)` values win. An empty cell keeps the default.",
        "",
        "| field | default | " + " | ".join(f"`{p}`" for p in presets) + " |",
        "|---|---|" + "---|" * len(presets),
    ]
    for n in touched:
        cells = [_code(p[n]) if n in p else "" for p in presets.values()]
        out.append(f"| `{n}` | {_code(defaults[n])} | " + " | ".join(cells) + " |")
    if mod.SEARCH_SPACE:  # what search: default and a tuned comparison search (sweeps/tuned.py)
        out += ["", f"### {fields.what} search space", "",
                "`search: default` in a sweep file, and every tuned comparison (`tune:`), search these fields "
                "(`SEARCH_SPACE` in its config.py); a range *around the default* is placed around the field's "
                "value on the trial's task.", "", "| field | distribution | range | source |", "|---|---|---|---|"]
        for n, d in mod.SEARCH_SPACE.items():
            where = (f"default / {d.around:g} to default × {d.around:g}" if d.around
                     else "one of " + ", ".join(f"{a:g}" if isinstance(a, float) else str(a) for a in d.args)
                     if d.kind == "choice" else " to ".join(map(str, d.args)))
            out.append(f"| `{n}` | {d.kind} | {where} | {_cell(d.source)} |")
    changeable = mod.changeable_space() if hasattr(mod, "changeable_space") else {}
    if changeable:  # what population-based training may change mid-run (sweeps/pbt.py)
        extra = {n: d for n, d in changeable.items() if n not in mod.SEARCH_SPACE}
        out += ["", f"Population-based training (`search: pbt`) changes {', '.join(f'`{n}`' for n in changeable)} "
                "mid-run (`CHANGEABLE`" + (": the search space and " + ", ".join(
                    f"`{n}` ({d.kind}, {_cell(d.source)})" for n, d in extra.items()) if extra else
                ": the search space") + ")."]
    return out


def config_markdown() -> str:
    """The text of docs/config.md."""
    from lac_rllib.algorithms.registry import ALGOS

    out = [
        "# Configuration fields of every algorithm",
        "",
        f"*Generated from each algorithm's `config.py`: do not edit; regenerate with `{REGENERATE}`.*",
        "",
        "Every field of LAC and of the baselines (`algo`: " + " | ".join(f"`{a}`" for a in ALGOS) + "), with its",
        "default, the values it accepts and its docstring. Source tags: [P] paper, [C] authors' code, [F] FOCOPS",
        "(for SAC-Lag: FSRL), [O] OmniSafe, [S] safety-starter-agents, [R] RLlib, [D] our decision; LAC's formulas",
        "and reasons are in [spec.md](spec.md), the baselines' in [baselines.md](baselines.md).",
    ]
    for i, algo in enumerate(ALGOS):
        out += _algo_section(algo, first=i == 0)

    out += ["", "## Tasks", "",
            "The registered tasks (`lac_rllib/tasks/`; spec.md §6): the preset each applies, its family",
            "(an algorithm may set fields per family: its presets above),",
            "where its per-step cost comes from, the cost limit b and the discount of its episode cost Ĵ_C",
            "(1 = a plain sum).",
            "", "| task | preset | family | cost per step | cost limit | episode cost discount |",
            "|---|---|---|---|---|---|"]
    from lac_rllib.tasks.user import FACTORY as USER_FACTORY

    for task_id in known_tasks():
        t = get_task(task_id)
        if t.factory == USER_FACTORY:  # a user's env registered in this process is not a built-in task
            continue
        out.append(f"| `{t.id}` | `{t.preset}` | {t.family} | {_cell(t.cost_source)} | {t.cost_limit:g} "
                   f"| {t.episode_cost_discount:g} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.stdout.write(config_markdown())
