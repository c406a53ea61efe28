"""Which hyperparameters matter, for the final return and for the final cost, in a search or a grid.

Each configuration (sweeps.reports.report.KEYS) becomes one completed trial of an in-memory Optuna study:
its field values as params, the mean over its scored seeds of the final return (or cost) as value.
Scored seeds are those sweeps.reports.report counts: failed trials (ERROR, or a NaN final return or cost)
and trials a scheduler stopped early (STOPPED, a score at a smaller budget) are left out. A grid
and a search are then the same thing to Optuna, and its importance evaluators and plots apply.

Evaluator: fANOVA (``FanovaImportanceEvaluator(seed=0)``: a random forest fitted to (params →
value), the share of the value's variance each param explains; Hutter et al. 2014). Compared on
synthetic sweeps where one field decides the value and one is noise (2-30 configurations; the
5 × 5 grid and 30-sample search of tests/sweeps/reports/test_importance.py among them): fANOVA ranks the
deciding field first from 9 configurations on (a 3 × 3 grid: 0.97) and does not depend on the
direction; PED-ANOVA (``PedAnovaImportanceEvaluator``) compares the top 10% of the trials with
all of them, which at 9-25 configurations is 1-2 trials: it scored the same 3 × 3 grid 0.50 /
0.50, and at 30 configurations its answer when minimising (0.63 / 0.37) was far from that when
maximising (0.97 / 0.03) the same values. fANOVA needs scikit-learn, which mlflow requires. Below MIN_CONFIGURATIONS
configurations with every varied field set, fANOVA's forest fits noise (4 random configurations:
0.52 / 0.48 where one field decides all), so no importance is given; nor when the objective is the
same for every configuration (fANOVA raises "zero total variance").

- Fields: the columns named in ``fields``, values parsed as the sweep logs them (MLflow params are
  text: "5" is 5, "true" is True). A field with one distinct value is dropped (it cannot matter
  here); one varied field has importance 1.0 by definition (no forest is fitted); none: {}.
- Distributions: numbers in [min, max], log-scaled when all > 0 and max/min >= LOG_RATIO (ints
  too: ``IntDistribution(log=True)``), ints as ints; bools, strings and mixed values categorical.
- Several tasks: returns and costs of different tasks are on different scales, so each value is
  standardised within its task (z-score) before the study is built; the study says so
  (``user_attrs["standardized_per_task"]``).

``importances`` returns :class:`Importances`, a dict with a ``reason`` attribute saying why an
objective is missing or trivial, for the parent run's note.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import optuna  # noqa: E402
import pandas as pd  # noqa: E402
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution  # noqa: E402

from lac_rllib.constrained.metrics import EPISODE_COST, EPISODE_RETURN  # noqa: E402
from sweeps.reports.configurations import KEYS  # noqa: E402
from sweeps.reports.configurations import is_na as _is_na  # noqa: E402
from sweeps.reports.configurations import prepared as _prepared  # noqa: E402

SEED = 0  # fANOVA's forest is seeded: the same sweep gives the same importances
MIN_CONFIGURATIONS = 5
LOG_RATIO = 100.0
#: objective → (trial column, study direction, axis text)
OBJECTIVES = {"return": (EPISODE_RETURN, "maximize", "final return"),
              "cost": (EPISODE_COST, "minimize", "final cost")}
# One HTML page for the four interactive plots: plotly.js (~4.8 MB) is embedded once, not four times.
PLOT_NAMES = ("importance.png", "importance.html", "parallel_return.png", "parallel_cost.png", "slice_return.png",
              "slice_cost.png")


class Importances(dict):
    """{"return": {field: importance}, "cost": {...}}, an objective left out when it has none;
    ``reason`` says why one is missing or trivial ("" when both were fitted)."""

    reason: str = ""


def _objective(objective: str) -> str:
    for name, (col, _, _) in OBJECTIVES.items():
        if objective in (name, col):
            return name
    raise ValueError(f"objective={objective!r}; accepted: {sorted(OBJECTIVES)} or their columns")


def _parse(v):
    """A field value as the sweep meant it: MLflow's text parsed as JSON where it is a scalar."""
    if isinstance(v, str):
        try:
            parsed = json.loads(v)
        except ValueError:
            return v
        return v if isinstance(parsed, (list, dict)) else parsed
    return v.item() if isinstance(v, np.generic) else v


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def infer_distribution(values: list):
    """The Optuna distribution of a field's values (module docstring); None when fewer than two
    distinct values."""
    vals = [v for v in values if not _is_na(v)]
    distinct = set(vals)
    if len(distinct) < 2:
        return None
    if all(_is_number(v) for v in vals):
        lo, hi = min(vals), max(vals)
        log = lo > 0 and hi / lo >= LOG_RATIO
        if all(isinstance(v, int) for v in vals):
            return IntDistribution(int(lo), int(hi), log=log)
        return FloatDistribution(float(lo), float(hi), log=log)
    if all(isinstance(v, bool) for v in vals):
        return CategoricalDistribution(sorted(distinct))
    return CategoricalDistribution(sorted({str(v) for v in vals}))


TASK, CONFIG, OBJECTIVE = "__task", "__config", "__objective"  # not field names


def _configurations(trials: pd.DataFrame, fields: list[str], column: str) -> tuple[pd.DataFrame, list[str]]:
    """One row per configuration: its task, config label, parsed field values and objective (the
    mean of ``column`` over its scored seeds; z-scored within task when there are several tasks),
    and the fields found in ``trials``."""
    df, failed = _prepared(trials)
    df = df[~failed & ~df["status"].astype(str).eq("STOPPED")]
    fields = [f for f in dict.fromkeys(fields) if f in df]
    rows = []
    for key, g in df.groupby(KEYS, dropna=False, sort=False):
        k = dict(zip(KEYS, key))
        row = {TASK: str(k["task"]), CONFIG: k["config"], OBJECTIVE: pd.to_numeric(g[column], errors="coerce").mean()}
        for f in fields:
            vals = [_parse(v) for v in g[f] if not _is_na(v)]
            row[f] = vals[0] if vals else None
        rows.append(row)
    conf = pd.DataFrame(rows, columns=[TASK, CONFIG, OBJECTIVE] + fields)
    conf = conf[conf[OBJECTIVE].notna()]
    # One order whatever the trials' (MLflow lists runs as they finished): the seeded forest's fit
    # depends on the order of its rows, so the same sweep would get different importances.
    keys = conf[[TASK, CONFIG, *fields]].to_dict("records")  # str() of each: a missing field is nan or None
    conf = conf.iloc[sorted(range(len(conf)), key=lambda i: [str(v) for v in keys[i].values()])]
    conf = conf.reset_index(drop=True)
    if conf[TASK].nunique() > 1:
        by_task = conf.groupby(TASK)[OBJECTIVE]
        std = by_task.transform(lambda s: s.std(ddof=0))
        conf[OBJECTIVE] = ((conf[OBJECTIVE] - by_task.transform("mean")) / std.where(std > 0, 1.0)).astype(float)
    return conf, fields


def _as_param(v, dist):
    """A parsed field value in the form its distribution holds."""
    if isinstance(dist, FloatDistribution):
        return float(v)
    if isinstance(dist, CategoricalDistribution) and all(isinstance(c, str) for c in dist.choices):
        return str(v)
    return v


def study_from_trials(trials: pd.DataFrame, fields: list[str], objective: str) -> optuna.Study:
    """An in-memory Optuna study with one completed trial per configuration (module docstring);
    ``objective`` is "return" or "cost" (or their columns). Its params are the varied fields;
    ``user_attrs``: objective, varied and dropped fields, standardized_per_task."""
    name = _objective(objective)
    column, direction, _ = OBJECTIVES[name]
    conf, present = _configurations(trials, fields, column)
    dists = {f: d for f in present if (d := infer_distribution(list(conf[f]))) is not None}
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(direction=direction, study_name=f"sweep-{name}")
    made = []
    for r in conf.to_dict("records"):
        params = {f: _as_param(r[f], d) for f, d in dists.items() if not _is_na(r[f])}
        made.append(optuna.trial.create_trial(params=params, distributions={f: dists[f] for f in params},
                                              value=float(r[OBJECTIVE]), user_attrs={"config": r[CONFIG]}))
    study.add_trials(made)
    study.set_user_attr("objective", name)
    study.set_user_attr("fields", list(dists))
    study.set_user_attr("dropped", [f for f in dict.fromkeys(fields) if f not in dists])
    study.set_user_attr("standardized_per_task", bool(conf[TASK].nunique() > 1))
    return study


def _importance(study: optuna.Study) -> tuple[dict[str, float], str]:
    """(importances, reason) of one study; {} with the reason when none can be given."""
    fields = study.user_attrs["fields"]
    if not fields:
        return {}, "no field varied"
    complete = [t for t in study.trials if all(f in t.params for f in fields)]
    values = np.array([t.value for t in complete], float)
    if len(complete) < 2:
        return {}, f"{len(complete)} configuration(s) with every varied field set"
    if np.ptp(values) == 0:
        return {}, "the same value for every configuration"
    if len(fields) == 1:
        return {fields[0]: 1.0}, f"only {fields[0]} varied: importance 1.0 by definition"
    if len(complete) < MIN_CONFIGURATIONS:
        return {}, f"{len(complete)} configurations, fewer than the {MIN_CONFIGURATIONS} fANOVA needs"
    try:
        imp = optuna.importance.get_param_importances(
            study, evaluator=optuna.importance.FanovaImportanceEvaluator(seed=SEED), params=fields)
    except Exception as e:  # never let a report fail on its importance
        return {}, f"fANOVA failed: {type(e).__name__}: {e}"
    return {k: float(v) for k, v in imp.items()}, ""


def importances(trials: pd.DataFrame, fields: list[str]) -> dict[str, dict[str, float]]:
    """{"return": {field: importance}, "cost": {...}} by fANOVA (importances of an objective sum to
    1, largest first); an :class:`Importances` whose ``reason`` explains a missing or trivial one.
    No varied field: {}."""
    out, reasons = Importances(), []
    for name in OBJECTIVES:
        imp, why = _importance(study_from_trials(trials, fields, name))
        if imp:
            out[name] = imp
        if why:
            reasons.append(f"{name}: {why}")
    out.reason = "; ".join(reasons)
    return out


def top_fields(imp: dict, k: int = 3) -> list[tuple[str, float]]:
    """The ``k`` most important fields of one objective's {field: importance} (``imp["return"]``),
    largest first, ties by name."""
    if any(isinstance(v, dict) for v in imp.values()):
        raise ValueError("top_fields takes one objective's importances, e.g. imp['return']")
    return sorted(((f, float(v)) for f, v in imp.items()), key=lambda fv: (-fv[1], fv[0]))[:k]


def importance_line(imp: dict, k: int = 3) -> str:
    """One markdown line for the parent run's note: the top fields per objective, or why there are none."""
    parts = [f"{name}: " + ", ".join(f"`{f}` {v:.2f}" for f, v in top_fields(imp[name], k))
             for name in OBJECTIVES if imp.get(name)]
    why = getattr(imp, "reason", "")
    text = ("**Hyperparameter importance** (fANOVA over configurations): " + "; ".join(parts) if parts
            else "**Hyperparameter importance:** none")
    return text + (f" ({why})" if why else "")


def importance_png(imp: dict, path) -> str | None:
    """Horizontal bars of each field's importance for return and for cost; None when there is none."""
    if not any(imp.get(n) for n in OBJECTIVES):
        return None
    fields = sorted({f for n in OBJECTIVES for f in imp.get(n, {})},
                    key=lambda f: -max(imp.get(n, {}).get(f, 0.0) for n in OBJECTIVES))[::-1]
    y = np.arange(len(fields))
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.55 * len(fields)))
    for dy, (name, colour) in zip((0.2, -0.2), (("return", "tab:blue"), ("cost", "tab:red"))):
        widths = [imp.get(name, {}).get(f, math.nan) for f in fields]
        bars = ax.barh(y + dy, widths, height=0.38, color=colour,
                       label=f"{OBJECTIVES[name][2]}" + ("" if imp.get(name) else " (none)"))
        ax.bar_label(bars, labels=["" if math.isnan(w) else f"{w:.2f}" for w in widths], fontsize=7, padding=2)
    ax.set_yticks(y, fields)
    ax.set(xlim=(0, 1.1), xlabel="importance (fANOVA: share of variance explained)",
           title="Which fields matter" + (f"\n{imp.reason}" if getattr(imp, "reason", "") else ""))
    ax.title.set_fontsize(9)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def _save_axes(ax, path) -> str:
    fig = np.ravel(ax)[0].figure
    fig.savefig(path, dpi=100, bbox_inches="tight")  # optuna's colour-bar axes do not take tight_layout
    plt.close(fig)
    return str(path)


def importance_plots(trials: pd.DataFrame, fields: list[str], out_dir) -> dict[str, str]:
    """Write importance.png and, per objective, the parallel-coordinate and slice plots (PNG, and all
    four on one HTML page, importance.html, plotly.js embedded once: the MLflow UI shows it offline);
    return {file name: path} of those written (``PLOT_NAMES``). An objective with fewer than two
    configurations or no varied field gets no plots."""
    from optuna.visualization import matplotlib as opt_mpl
    from optuna.visualization import plot_parallel_coordinate, plot_slice

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths, divs = {}, []
    made = importance_png(importances(trials, fields), out / "importance.png")
    if made:
        paths["importance.png"] = made
    for name, (_, _, text) in OBJECTIVES.items():
        study = study_from_trials(trials, fields, name)
        params = study.user_attrs["fields"]
        if not params or len(study.trials) < 2:
            continue
        target = text + (" (z-score within task)" if study.user_attrs["standardized_per_task"] else "")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            for kind, html_fn, png_fn in (("parallel", plot_parallel_coordinate, opt_mpl.plot_parallel_coordinate),
                                          ("slice", plot_slice, opt_mpl.plot_slice)):
                fig = html_fn(study, params=params, target_name=target)
                fig.update_layout(title=f"{kind.capitalize()} plot: {target} per configuration")
                divs.append(fig.to_html(include_plotlyjs=not divs, full_html=False))
                png = out / f"{kind}_{name}.png"
                with matplotlib.rc_context():  # optuna's plots call plt.style.use("ggplot"): keep it to them
                    paths[png.name] = _save_axes(png_fn(study, params=params, target_name=target), png)
    if divs:
        html = out / "importance.html"
        html.write_text("<html><head><meta charset='utf-8'><title>Which hyperparameters matter</title></head><body>"
                        + "".join(divs) + "</body></html>", encoding="utf-8")
        paths[html.name] = str(html)
    return paths
