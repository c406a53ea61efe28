"""Reports for a finished LAC sweep, attached by the caller to the sweep's MLflow parent run.

Turns the per-trial table and per-iteration curves into a per-configuration summary (CSV,
markdown, best feasible configuration as JSON) and the plots of the paper's ablations
(docs/spec.md §7: box plots of the final cost per swept value, Figs. 4/6/7; mean learning curves).

Conventions:
- A configuration is (group, param, value, task); its rows are its seeds.
- A trial *failed* if its status is "ERROR" or its final episode_return / episode_cost is NaN.
  Failed trials count in ``n_failed`` and are left out of every statistic and plot. Trials a
  scheduler (ASHA) stopped early count in ``n_stopped`` and are left out of the statistics too:
  their score is from a smaller budget.
- Spreads are the sample std over seeds (ddof=1); with one finished seed it is NaN and the
  markdown shows "14.20 ± –". Curve bands use the same std and are omitted for a single seed.
- Plots get one panel (row, for curves) per group, split per task if a group spans several.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lac_rllib.algorithms.registry import ALGOS, DEFAULT_ALGO
from lac_rllib.constrained.metrics import COST_LIMIT, ENV_STEPS, EPISODE_COST, EPISODE_RETURN, FEASIBLE  # noqa: E402
from sweeps.reports.configurations import KEYS  # noqa: E402
from sweeps.reports.configurations import ci as _ci  # noqa: E402
from sweeps.reports.configurations import fmt_num as _fmt_num  # noqa: E402
from sweeps.reports.configurations import fmt_value as _fmt_value  # noqa: E402
from sweeps.reports.configurations import is_na as _is_na  # noqa: E402
from sweeps.reports.configurations import metric_name as _metric_name  # noqa: E402
from sweeps.reports.configurations import prepared as _prepared  # noqa: E402
from sweeps.reports.configurations import value_key as _value_key  # noqa: E402
from sweeps.reports.verdicts import STAT_COLUMNS, configuration_feasible, seed_statistics, seeds_line  # noqa: E402
from sweeps.score import EVAL_COST, EVAL_RETURN, TRAIN_COST, TRAIN_RETURN, described  # noqa: E402

STATS = ["n_seeds", "n_failed", "n_stopped", "return_mean", "return_std", "cost_mean", "cost_std",
         "cost_limit", "feasible_fraction", "feasible", "objective_mean", "is_default",
         *STAT_COLUMNS, "n_eval_scored", *(f"{c}_mean" for c in (TRAIN_RETURN, TRAIN_COST, EVAL_RETURN, EVAL_COST))]


def _pm(mean, std) -> str:
    """Mean ± std; the std shows "–" when undefined (one seed), all "–" without finished seeds."""
    return "–" if _is_na(mean) else f"{_fmt_num(mean)} ± {_fmt_num(std)}"


def summarize(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (group, param, value, task) with seed statistics; see the module conventions."""
    df, failed = _prepared(trials)
    rows = []
    stopped = df["status"].astype(str).eq("STOPPED") & ~failed  # ASHA: a score at an earlier budget
    scored = df[~(failed | stopped)]
    for key, g in df.groupby(KEYS, dropna=False, sort=False):
        ok = g[~(failed | stopped).loc[g.index]]
        ret, cost = (pd.to_numeric(ok[c], errors="coerce") for c in (EPISODE_RETURN, EPISODE_COST))
        limit = pd.to_numeric(g[COST_LIMIT], errors="coerce").median()
        base = scored[scored["default"] & (scored["task"] == g["task"].iloc[0])]
        rows.append(dict(
            zip(KEYS, key), n_seeds=len(ok), n_failed=int(failed.loc[g.index].sum()),
            n_stopped=int(stopped.loc[g.index].sum()),
            return_mean=ret.mean(), return_std=ret.std(ddof=1),
            cost_mean=cost.mean(), cost_std=cost.std(ddof=1), cost_limit=limit,
            feasible_fraction=pd.to_numeric(ok[FEASIBLE], errors="coerce").mean(),
            feasible=configuration_feasible(cost[ret.notna()], limit),  # the one rule (verdicts.py)
            objective_mean=pd.to_numeric(ok["objective"], errors="coerce").mean(),
            is_default=bool(g["default"].any()),
            # What the seeds were ranked on (sweeps/score.py), and both scores' means beside.
            n_eval_scored=int(ok["score"].eq("eval").sum()) if "score" in ok else 0,
            **{f"{c}_mean": pd.to_numeric(ok[c], errors="coerce").mean() if c in ok else float("nan")
               for c in (TRAIN_RETURN, TRAIN_COST, EVAL_RETURN, EVAL_COST)},
            **seed_statistics(ret, cost, *(pd.to_numeric(base[c], errors="coerce") for c in
                                           (EPISODE_RETURN, EPISODE_COST)) if len(base) else (None, None))))
    # A total order (a ladder's limits, then the label): the report never follows MLflow's run order.
    rows.sort(key=lambda r: (str(r["group"]), _value_key(r["value"]), str(r["task"]), r["param"],
                             _value_key(r["cost_limit"]), str(r["config"])))
    return pd.DataFrame(rows, columns=KEYS + STATS)


def score_text(summary: pd.DataFrame) -> str:
    """What the summary's configurations were ranked on (sweeps/score.py), from their seeds' counts."""
    n_eval = int(pd.to_numeric(summary.get("n_eval_scored", 0), errors="coerce").fillna(0).sum())
    n_all = int(pd.to_numeric(summary["n_seeds"], errors="coerce").fillna(0).sum())
    return described(["eval"] * n_eval + ["train"] * (n_all - n_eval))


def best_configuration(summary: pd.DataFrame) -> dict | None:
    """The feasible configuration (sweeps/reports/verdicts.py's rule) with the highest return_mean
    (JSON-ready dict), or None."""
    ok = summary[summary["feasible"].astype(bool) & summary["return_mean"].notna()]
    if ok.empty:
        return None
    row = ok.loc[ok["return_mean"].idxmax()]
    plain = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in row.items()}
    return {k: (None if _is_na(v) else v) for k, v in plain.items()}


#: The metrics a sweep's parent run gets when it ends (MLflow's runs table sorts and charts sweeps by them).
PARENT_METRICS = ("best_feasible_return", "best_feasible_cost", "feasible_configurations", "configurations",
                  "trials_finished", "trials_stopped", "trials_failed")


def parent_metrics(summary: pd.DataFrame) -> dict[str, float]:
    """The parent run's metrics (:data:`PARENT_METRICS`) from the sweep's summary: the best
    feasible configuration's return and cost (left out when none is feasible, so a sweep
    without one sorts last rather than at a made-up number), how many configurations are
    feasible, and the trials finished, stopped early and failed. A sweep over several tasks gets
    the best per task instead (``best_feasible_return/<task>``): returns of different tasks do
    not compare."""
    out = {"feasible_configurations": float(summary["feasible"].astype(bool).sum()),
           "configurations": float(len(summary)),
           "trials_finished": float(summary["n_seeds"].sum()),
           "trials_stopped": float(summary["n_stopped"].sum()),
           "trials_failed": float(summary["n_failed"].sum())}
    tasks = list(dict.fromkeys(summary["task"]))
    for task in tasks:
        best = best_configuration(summary[summary["task"] == task])
        if best is None:
            continue
        suffix = "" if len(tasks) == 1 else f"/{_metric_name(task)}"
        out[f"best_feasible_return{suffix}"] = float(best["return_mean"])
        out[f"best_feasible_cost{suffix}"] = float(best["cost_mean"])
    return out


def constraints_note(trials: pd.DataFrame) -> str:
    """With several constraints, what the cost columns are (the joint rule, sweeps/score.py); else ''."""
    names = [c.partition("/")[2] for c in trials.columns if c.startswith("cost_limit/")]
    if not names:
        return ""
    along = sorted({str(v) for v in trials.get("ladder_constraint", pd.Series(dtype=str)).dropna() if v})
    ladder = (f" On the ladder along {', '.join(along)} both are shifted by the rung's limit b: the cost is "
              "b + that excess, held to b." if along else "")
    return (f"Several constraints ({', '.join(names)}): a trial's cost is the joint rule's max_k (J_k − b_k), its "
            "largest excess over a constraint's limit (negative: the tightest one's slack), held to 0; each "
            f"constraint's score is in trials.csv (`episode_cost/NAME`, `cost_limit/NAME`).{ladder}\n\n")


def best_lines(summary: pd.DataFrame) -> list[str]:
    """The best feasible configuration, one line; over a ladder of limits one per limit (a
    configuration is judged at its own limit: returns at different limits do not compare)."""
    none = "none (no configuration has ≥ 80% of its seeds within the limit)"
    limits = pd.to_numeric(summary["cost_limit"], errors="coerce")
    if limits.nunique() < 2:
        best = best_configuration(summary)
        return [f"**Best feasible configuration:** {_describe(best) if best else none}"]
    out = []
    for b in sorted(limits.dropna().unique()):
        best = best_configuration(summary[limits == b])
        out.append(f"**Best feasible configuration at limit {_fmt_value(b)}:** {_describe(best) if best else none}")
    return out


def _describe(cfg: dict) -> str:
    # A group of several algorithms (a ladder's ``algo: [...]``) is named by its configuration's label.
    what = (f"{cfg['group']} {cfg['param']}={_fmt_value(cfg['value'])}" if cfg["param"] else
            cfg.get("config") or cfg["group"])
    return (f"{what} on {cfg['task']}: return {_pm(cfg['return_mean'], cfg['return_std'])}, cost "
            f"{_pm(cfg['cost_mean'], cfg['cost_std'])} (limit {_fmt_num(cfg['cost_limit'])}), "
            f"{cfg['n_seeds']} seeds")


def _poi(x) -> str:
    return "–" if _is_na(x) else f"{float(x):.2f}"


def _what(r: dict) -> str:
    what = f"{r['param']}={_fmt_value(r['value'])}" if r["param"] else (r.get("config") or "–")
    return what + (" (default)" if r.get("is_default") else "")


def _feasible(r: dict) -> str:
    if not r["n_seeds"]:
        return "no (all failed)"
    n_ok = "–" if _is_na(r["feasible_fraction"]) else round(r["feasible_fraction"] * r["n_seeds"])
    return f"{n_ok}/{r['n_seeds']}"


STAT_HEADER = ("return mean [95%] | return IQM | cost mean [95%] | cost IQM "
               "| feasible seeds | P(return > default) | P(cost < default)")


def _stat_cells(r: dict) -> list[str]:
    return [_ci(r["return_mean"], r["return_mean_ci_low"], r["return_mean_ci_high"]),
            _fmt_num(r["return_iqm"]),
            _ci(r["cost_mean"], r["cost_mean_ci_low"], r["cost_mean_ci_high"]),
            _fmt_num(r["cost_iqm"]),
            _feasible(r), _poi(r["poi_return_vs_default"]), _poi(r["poi_cost_vs_default"])]


def _seeds(r: dict) -> str:
    return (f"{r['n_seeds']}" + (f" (+{r['n_failed']} failed)" if r["n_failed"] else "")
            + (f" (+{r['n_stopped']} stopped early)" if r["n_stopped"] else ""))


def markdown_table(summary: pd.DataFrame) -> str:
    """Markdown table of the summary (one row per configuration), the seeds line and the best one."""
    def cell(x) -> str:
        return str(x).replace("|", "\\|")

    lines = [f"| group | configuration | task | seeds | {STAT_HEADER} | return (mean ± std) | cost (mean ± std) "
             "| limit |", "|---|---|---|---:|" + "---:|" * 7 + "---:|---:|---:|"]
    for r in summary.to_dict("records"):
        cols = [r["group"], _what(r), r["task"], _seeds(r), *_stat_cells(r),
                _pm(r["return_mean"], r["return_std"]), _pm(r["cost_mean"], r["cost_std"]), _fmt_num(r["cost_limit"])]
        lines.append("| " + " | ".join(cell(c) for c in cols) + " |")
    comparison = algorithm_comparison(summary)
    lines += ["", f"Scores: {score_text(summary)}. " + seeds_line([int(n) for n in summary["n_seeds"] if n]), ""]
    lines += [comparison] if comparison else []
    lines += [cell(line) for line in best_lines(summary)]
    return "\n".join(lines) + "\n"


def algorithm_comparison(summary: pd.DataFrame) -> str:
    """The algorithms of a compare sweep side by side, per task (``""`` when the sweep compares none):
    return and cost (mean and IQM with their intervals), feasible seeds, P(LAC beats X) on return
    and on cost (LAC runs the defaults, the comparisons' reference: P(LAC beats X) = 1 − P(X beats
    LAC), ties counting one half), and which algorithm is best within the limit."""
    rows = summary[summary["param"].astype(str) == "algo"]
    if rows.empty or rows["value"].nunique() < 2:
        return ""
    out = []
    for task, g in rows.groupby("task", sort=False):
        lines = [f"**Algorithms on `{task}`** (final return and cost over seeds; limit "
                 f"{_fmt_num(g['cost_limit'].median())}):", "",
                 "| algorithm | seeds | return mean [95%] | return IQM | cost mean [95%] | "
                 "cost IQM | feasible seeds | P(LAC return > X) | P(LAC cost < X) |",
                 "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        order = {a: i for i, a in enumerate(ALGOS)}  # the registry's order, LAC first; a user's module after
        for r in sorted(g.to_dict("records"), key=lambda r: (order.get(r["value"], len(order)), str(r["value"]))):
            lac = r["value"] == DEFAULT_ALGO
            beats = ["–", "–"] if lac else [_poi(1 - r[k]) if not _is_na(r[k]) else "–"
                                            for k in ("poi_return_vs_default", "poi_cost_vs_default")]
            lines.append("| " + " | ".join([str(r["value"]), _seeds(r), *_stat_cells(r)[:5], *beats]) + " |")
        ok = g[g["feasible"].astype(bool) & g["return_mean"].notna()]
        if ok.empty:
            lines += ["", "**Best within the limit:** none (no algorithm has ≥ 80% of its seeds within the limit)"]
        else:
            best = ok.loc[ok["return_mean"].idxmax()]
            lines += ["", f"**Best within the limit:** {best['value']}, return "
                          f"{_ci(best['return_mean'], best['return_mean_ci_low'], best['return_mean_ci_high'])}, "
                          f"cost {_ci(best['cost_mean'], best['cost_mean_ci_low'], best['cost_mean_ci_high'])}"]
        out.append("\n".join(lines))
    return "\n\n".join(out) + "\n"


def note_markdown(summary: pd.DataFrame, heading: str, footer: str = "", limit: int = 7900, extra: str = "") -> str:
    """The parent run's note: what the sweep found, readable on its MLflow page; ``extra`` (the
    importances, the safety statistics, ...) goes below the best configuration.

    MLflow cuts a tag at 8000 characters, so rows beyond ``limit`` are left to summary.md.
    """
    tasks = summary["task"].astype(str).unique() if len(summary) else []
    one_task = len(tasks) == 1
    head = [heading, "", *best_lines(summary), ""]
    if extra:
        head += [extra, ""]
    if one_task:
        head += [f"Task `{tasks[0]}`; final return and cost per configuration over its seeds:", ""]
    head += [f"Scores: {score_text(summary)}. " + seeds_line([int(n) for n in summary["n_seeds"] if n]), ""]
    cols = "| group | configuration | " + ("" if one_task else "task | ") + "seeds | " + STAT_HEADER + " |"
    rows = [cols, "|" + "---|" * (cols.count("|") - 1)]
    for r in summary.to_dict("records"):
        cells = [r["group"], _what(r)] + ([] if one_task else [r["task"]]) + [_seeds(r), *_stat_cells(r)]
        rows.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    tail = ["", footer] if footer else []
    text = "\n".join(head + rows + tail)
    while len(text) > limit and len(rows) > 2:  # keep the head and the footer, drop rows from the end
        rows.pop()
        text = "\n".join(head + rows + ["", f"… {len(summary) - len(rows) + 2} more rows in summary/summary.md"] + tail)
    return text if len(text) <= limit else text[:limit - 40] + "\n… (the rest: summary/summary.md)"


def _panels(trials: pd.DataFrame, swept_only: bool) -> list[tuple[str, str, pd.DataFrame]]:
    """(label, param, finished trials) per group, split per task when a group spans several."""
    df, failed = _prepared(trials)
    df = df[~failed]
    out = []
    for group in sorted(df["group"].astype(str).unique()):
        g = df[df["group"].astype(str) == group]
        param = next((p for p in g["param"] if p), "")
        if swept_only and not param:
            continue
        tasks = sorted(g["task"].astype(str).unique())
        for task in tasks:
            out.append((group if len(tasks) == 1 else f"{group} ({task})", param,
                        g[g["task"].astype(str) == task]))
    return out


def _values(sub: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """(value label, rows) for each distinct swept value of ``sub``, in sorted order."""
    labels = sub["value"].map(_fmt_value)
    firsts = {lab: v for lab, v in zip(labels[::-1], sub["value"][::-1])}
    return [(lab, sub[labels == lab]) for lab in sorted(firsts, key=lambda k: _value_key(firsts[k]))]


def _limit(*series: pd.Series) -> float:
    """Median of the first series that has a numeric value (NaN if none)."""
    for s in series:
        v = pd.to_numeric(s, errors="coerce").median()
        if not _is_na(v):
            return float(v)
    return math.nan


def _save(fig, path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def cost_box_plots(trials: pd.DataFrame, path) -> str | None:
    """Box plots of the final episode cost per swept value, one subplot per swept group."""
    panels = _panels(trials, swept_only=True)
    if not panels:
        return None
    ncols = min(3, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, 4 * nrows), squeeze=False)
    rng = np.random.default_rng(0)  # jitter of the seed dots only
    for ax, (label, param, sub) in zip(axes.ravel(), panels):
        vals = _values(sub)
        data = [pd.to_numeric(rows[EPISODE_COST]).to_numpy(float) for _, rows in vals]
        pos = np.arange(1, len(vals) + 1)
        ax.boxplot(data, positions=pos, widths=0.5)
        for p, d in zip(pos, data):
            ax.plot(p + rng.uniform(-0.12, 0.12, len(d)), d, "o", ms=4, alpha=0.6, color="tab:blue")
        ax.set_xticks(pos, [lab for lab, _ in vals])
        limit = _limit(sub[COST_LIMIT])
        if not math.isnan(limit):
            ax.axhline(limit, ls="--", color="tab:red", label=f"cost limit ({limit:g})")
            ax.legend(loc="best", fontsize=8)
            ys = np.concatenate(data + [np.array([limit])])
            pad = 0.08 * (ys.max() - ys.min() or 1.0)  # keep the limit line off the frame edge
            ax.set_ylim(ys.min() - pad, ys.max() + pad)
        ax.set(title=f"{label}: final cost per {param}", xlabel=param, ylabel="final episode cost")
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    return _save(fig, path)


def aggregate_plots(summary: pd.DataFrame, path) -> str | None:
    """Per configuration: mean (with its 95% interval) and IQM of the final return and cost (the
    statistics of summary.md), one row per group; the cost limit dashed, the default marked."""
    df = summary[summary["n_seeds"] > 0]
    if df.empty:
        return None
    groups = list(dict.fromkeys(df["group"].astype(str)))
    fig, axes = plt.subplots(len(groups), 2, figsize=(12, 3.4 * len(groups)), squeeze=False)
    for (ax_r, ax_c), group in zip(axes, groups):
        g = df[df["group"].astype(str) == group].reset_index(drop=True)
        labels = [_what(r) for r in g.to_dict("records")]
        x = np.arange(len(g))
        for ax, name in ((ax_r, "return"), (ax_c, "cost")):
            point = g[f"{name}_mean"].to_numpy(float)
            lo, hi = g[f"{name}_mean_ci_low"].to_numpy(float), g[f"{name}_mean_ci_high"].to_numpy(float)
            err = np.vstack([np.where(np.isnan(lo), 0, point - lo), np.where(np.isnan(hi), 0, hi - point)])
            ax.errorbar(x - 0.12, point, yerr=err, fmt="o", capsize=4, label="mean [95%, t]")
            ax.plot(x + 0.12, g[f"{name}_iqm"].to_numpy(float), "s", label="IQM")
            ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=8)
            ax.set(title=f"{group}: final {name} per configuration", ylabel=f"final episode {name}")
        limit = _limit(g["cost_limit"])
        if not math.isnan(limit):
            ax_c.axhline(limit, ls="--", color="tab:red", label=f"cost limit ({limit:g})")
        ax_r.legend(fontsize=8, loc="best")
        ax_c.legend(fontsize=8, loc="best")
    return _save(fig, path)


def _xy(frame: pd.DataFrame, col: str) -> tuple[np.ndarray, np.ndarray]:
    """(env_steps, col) of a curve, numeric, NaN-free, sorted by env_steps."""
    if frame is None or ENV_STEPS not in frame or col not in frame:
        return np.empty(0), np.empty(0)
    d = frame[[ENV_STEPS, col]].apply(pd.to_numeric, errors="coerce").dropna()
    d = d.sort_values(ENV_STEPS)
    return d[ENV_STEPS].to_numpy(float), d[col].to_numpy(float)


def _mean_curve(frames: list[pd.DataFrame], col: str, n: int = 200):
    """(grid, mean, std) of ``col`` over seeds interpolated on a common env_steps grid, or None.

    The grid spans the range all seeds cover (the union if they do not overlap); std is ddof=1,
    NaN where fewer than two seeds are present.
    """
    series = [s for s in (_xy(f, col) for f in frames) if s[0].size]
    if not series:
        return None
    lo, hi = max(x[0] for x, _ in series), min(x[-1] for x, _ in series)
    if hi < lo:
        lo, hi = min(x[0] for x, _ in series), max(x[-1] for x, _ in series)
    grid = np.linspace(lo, hi, n) if hi > lo else np.array([lo])
    ys = np.array([np.where((grid >= x[0]) & (grid <= x[-1]), np.interp(grid, x, y), np.nan)
                   for x, y in series])
    cnt = (~np.isnan(ys)).sum(0)
    mean = np.where(cnt > 0, np.nansum(ys, 0) / np.maximum(cnt, 1), np.nan)
    var = np.nansum((ys - mean) ** 2, 0) / np.maximum(cnt - 1, 1)
    return grid, mean, np.where(cnt > 1, np.sqrt(var), np.nan)


def learning_curves(trials: pd.DataFrame, curves: dict, path) -> str | None:
    """Mean ± std return and cost vs env steps; one row per group, one line per swept value."""
    rows = []
    for label, param, sub in _panels(trials, swept_only=False):
        lines = [(lab, [curves[t] for t in r["trial_id"] if t in curves]) for lab, r in _values(sub)]
        lines = [(lab, fr) for lab, fr in lines
                 if any(_xy(f, c)[0].size for f in fr for c in (EPISODE_RETURN, EPISODE_COST))]
        if lines:
            rows.append((label, param, sub, lines))
    if not rows:
        return None
    fig, axes = plt.subplots(len(rows), 2, figsize=(12, 3.6 * len(rows)), squeeze=False)
    for (label, param, sub, lines), (ax_r, ax_c) in zip(rows, axes):
        for i, (lab, frames) in enumerate(lines):
            name = f"{param}={lab} (n={len(frames)})" if param else f"mean of {len(frames)} seeds"
            for ax, col in ((ax_r, EPISODE_RETURN), (ax_c, EPISODE_COST)):
                m = _mean_curve(frames, col)
                if m is None:
                    continue
                x, mean, std = m
                ax.plot(x, mean, color=f"C{i % 10}", label=name, marker="o" if x.size == 1 else None)
                ax.fill_between(x, mean - std, mean + std, color=f"C{i % 10}", alpha=0.2)
        limit = _limit(sub[COST_LIMIT], *(f[COST_LIMIT] for _, fr in lines for f in fr
                                          if isinstance(f, pd.DataFrame) and COST_LIMIT in f))
        if not math.isnan(limit):
            ax_c.axhline(limit, ls="--", color="tab:red", label=f"cost limit ({limit:g})")
        ax_r.set(title=f"{label}: episode return", xlabel="env steps", ylabel="episode return")
        ax_c.set(title=f"{label}: episode cost", xlabel="env steps", ylabel="episode cost")
        ax_r.legend(fontsize=8, loc="best")
        ax_c.legend(fontsize=8, loc="best")
    return _save(fig, path)


def trial_curve(curve_df: pd.DataFrame, path, title: str) -> str:
    """A single trial's return and cost vs env steps (cost limit dashed), saved as PNG."""
    fig, (ax_r, ax_c) = plt.subplots(1, 2, figsize=(11, 3.6))
    for ax, col, name in ((ax_r, EPISODE_RETURN, "episode return"),
                          (ax_c, EPISODE_COST, "episode cost")):
        x, y = _xy(curve_df, col)
        ax.plot(x, y, marker="o" if x.size == 1 else None, label=name)
        ax.set(title=name, xlabel="env steps", ylabel=name)
    limit = _limit(curve_df[COST_LIMIT]) if COST_LIMIT in curve_df else math.nan
    if not math.isnan(limit):
        ax_c.axhline(limit, ls="--", color="tab:red", label=f"cost limit ({limit:g})")
    ax_c.legend(fontsize=8, loc="best")
    fig.suptitle(title)
    return _save(fig, path)


def with_safety(summary: pd.DataFrame, trials: pd.DataFrame, curves: dict) -> pd.DataFrame:
    """The summary with each configuration's safety statistics (sweeps/reports/safety.py: P(feasible at the
    end) with its Wilson interval, the violation over training, the worst iteration, the spread of
    the final cost), its place on the reward-cost frontier, its chain-health flags and how its
    multiplier behaved (sweeps/reports/multiplier.py: the seeds' mean overshoot, swing and fractions
    of iterations with ν at 0 and at its bound; steps to feasible and the cost rate are safety's)."""
    from sweeps.reports.chain_health import chain_flags
    from sweeps.reports.frontier import frontier
    from sweeps.reports.multiplier import behaviour_table
    from sweeps.reports.safety import safety_table

    def key(values) -> tuple:
        return tuple("" if _is_na(v) else str(v) for v in values)

    safety = safety_table(trials, curves)
    by_key = {key(r[k] for k in KEYS): r for r in safety.to_dict("records")}
    cols = [c for c in safety.columns if c not in KEYS and c != "n_seeds"]
    out = summary.copy()
    rows = [by_key.get(key(r[k] for k in KEYS), {}) for r in out.to_dict("records")]
    for c in cols:
        out[c] = [r.get(c, math.nan) for r in rows]
    out["on_frontier"] = frontier(out).to_numpy()
    flags = {key(k): v for k, v in chain_flags(trials).items()}
    out["chain_flags"] = [flags.get(key(r[k] for k in KEYS), "") for r in out.to_dict("records")]
    behaviour = behaviour_table(_prepared(trials)[0], curves, KEYS)
    by_key = {key(r[k] for k in KEYS): r for r in behaviour.to_dict("records")}
    for c in ("overshoot", "swing", "nu_at_zero", "nu_at_bound"):  # the others are safety's columns
        out[c] = [by_key.get(key(r[k] for k in KEYS), {}).get(c, math.nan) for r in out.to_dict("records")]
    return out


def safety_markdown(summary: pd.DataFrame, trials: pd.DataFrame, curves: dict) -> str:
    """Per configuration: P(feasible at the end) [Wilson 95%], the violation during training and the
    worst iteration, the final cost's spread, and chain-health flags where there are any."""
    s = summary if "p_feasible" in summary else with_safety(summary, trials, curves)  # once per report
    lines = ["**Safety per configuration** (P(feasible at the end) with a Wilson 95% interval; violation = "
             "Σ over iterations of max(0, cost − limit), mean over seeds; the worst iteration over its seeds; "
             "during training: the cost rate (cost per env step), the env steps to the first feasible iteration "
             "(mean over the seeds that got there) and the longest run of infeasible iterations):", "",
             "| group, configuration | P(feasible) [95%] | violation | worst iteration (excess @ env steps) "
             "| final cost min–max | cost rate | steps to feasible | longest infeasible run | frontier | chain |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|---|"]
    for r in s.to_dict("records"):
        p = "–" if _is_na(r.get("p_feasible")) else (f"{r['p_feasible']:.2f} [{r['p_feasible_low']:.2f}, "
                                                    f"{r['p_feasible_high']:.2f}]")
        worst = "–" if _is_na(r.get("worst_excess")) else f"{r['worst_excess']:+.2f} @ {r['worst_env_steps']:,.0f}"
        spread = "–" if _is_na(r.get("final_cost_min")) else f"{r['final_cost_min']:.2f}–{r['final_cost_max']:.2f}"
        what = f"{r['group']} {_what(r)}" if r["param"] else r["group"] + (" (default)" if r.get("is_default") else "")
        never = int(r.get("never_feasible") or 0)
        reach = "never" if _is_na(r.get("steps_to_feasible")) else f"{r['steps_to_feasible']:,.0f}"
        reach += f" ({never} seed{'s' if never > 1 else ''} never)" if never and reach != "never" else ""
        run = "–" if _is_na(r.get("longest_infeasible")) else f"{r['longest_infeasible']:.0f} iterations"
        cells = [what, p, _fmt_num(r.get("violation_total")), worst, spread, _fmt_rate(r.get("cost_rate")), reach,
                 run, "yes" if r.get("on_frontier") else "", r.get("chain_flags") or ""]
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _fmt_rate(x) -> str:
    """A cost per env step (small numbers: three significant digits)."""
    return "–" if _is_na(x) else f"{x:.3g}"


def nothing_feasible_markdown(summary: pd.DataFrame) -> str:
    """When no configuration is feasible (sweeps/reports/verdicts.py's rule), a line saying so and
    naming the least infeasible one (the smallest mean cost over its limit), to lead the note; ""
    otherwise."""
    ok = summary[summary["cost_mean"].notna()]
    if ok.empty or ok["feasible"].astype(bool).any():
        return ""
    least = ok.loc[(ok["cost_mean"] - ok["cost_limit"]).idxmin()]
    return (f"**Nothing is feasible**: no configuration has ≥ 80% of its seeds within its limit. The least infeasible: "
            f"{_describe(least.to_dict())}, {_fmt_num(least['cost_mean'] - least['cost_limit'])} over.")


def importance_markdown(trials: pd.DataFrame, fields: tuple[str, ...]) -> str:
    """The top three fields for return and for cost (fANOVA over the configurations), or ""
    when the sweep varies nothing."""
    if not fields:
        return ""
    from sweeps.reports.importance import importance_line, importances

    return importance_line(importances(trials, list(fields)))


def pareto_markdown(pareto: list[dict]) -> str:
    """A multi-objective search's Pareto set, one row per configuration."""
    lines = [f"**Pareto set** of the multi-objective search ({len(pareto)} configurations, return up, cost down; "
             "the limit as a constraint):", "", "| trial | sampled values | return | cost | within the limit |",
             "|---:|---|---:|---:|---|"]
    for t in sorted(pareto, key=lambda t: t[EPISODE_COST]):
        values = ", ".join(f"{k}={_fmt_value(v)}" for k, v in t["params"].items())
        c = t.get("constraint")
        lines.append(f"| {t['number']} | {values} | {_fmt_num(t[EPISODE_RETURN])} | {_fmt_num(t[EPISODE_COST])} | "
                     f"{'–' if c is None else 'yes' if c <= 0 else 'no'} |")
    return "\n".join(lines) + "\n"


def write_sweep_reports(trials: pd.DataFrame, curves: dict, out_dir, fields: tuple[str, ...] = ()) -> dict[str, str]:
    """Write summary.csv/.md (with the safety statistics), best.json, trials.csv, the plots, the
    reward-cost frontier (PNG and interactive HTML) and, where the sweep varies ``fields``, which of
    them matter (importance.png/.html); return {file name: path}."""
    from sweeps.reports.constraints import constraints_markdown, constraints_table
    from sweeps.reports.frontier import frontier_html, frontier_png
    from sweeps.reports.importance import importance_plots

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = with_safety(summarize(trials), trials, curves)
    best = best_configuration(summary)
    summary.to_csv(out / "summary.csv", index=False)
    per_constraint = constraints_markdown(trials)
    (out / "summary.md").write_text(constraints_note(trials) + markdown_table(summary) + "\n"
                                    + (per_constraint + "\n" if per_constraint else "")
                                    + safety_markdown(summary, trials, curves)
                                    + ("\n" + importance_markdown(trials, fields) if fields else ""), encoding="utf-8")
    (out / "best.json").write_text(json.dumps(best if best else {"best": None}, indent=2) + "\n")
    trials.to_csv(out / "trials.csv", index=False)
    paths = {n: str(out / n) for n in ("summary.csv", "summary.md", "best.json", "trials.csv")}
    if not (per := constraints_table(trials)).empty:  # several constraints: the table per constraint
        per.to_csv(out / "constraints.csv", index=False)
        paths["constraints.csv"] = str(out / "constraints.csv")
    for name, made in (("cost_boxplots.png", cost_box_plots(trials, out / "cost_boxplots.png")),
                       ("aggregates.png", aggregate_plots(summary, out / "aggregates.png")),
                       ("learning_curves.png", learning_curves(trials, curves, out / "learning_curves.png")),
                       ("frontier.png", frontier_png(summary, out / "frontier.png")),
                       ("frontier.html", frontier_html(summary, out / "frontier.html"))):
        if made:
            paths[name] = made
    if fields:
        paths.update(importance_plots(trials, list(fields), out))
    return paths
