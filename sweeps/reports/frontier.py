"""The reward-cost frontier of a sweep: which configurations are worth having.

A configuration (a row of ``sweeps.reports.report.summarize``) is *feasible* by the one rule of
sweeps/reports/verdicts.py (its ``feasible`` column: ≥ 80% of its seeds within the limit) and *on
the frontier* when it is feasible and no other feasible configuration of the same task has a return
at least as high and a cost at least as low, with one of the two strictly better. Two configurations
with the same return and cost do not dominate each other: both stay on the frontier. A configuration
without finished seeds (NaN return or cost) or without a limit is never on it. Why feasible only: a
constrained problem ranks an over-limit policy below every within-limit one, however high its
return.

The plot shows every configuration on (cost, return) axes with its 95% intervals in
both directions (sweeps/reports/verdicts.py), one panel per task: the cost limit dashed, the frontier starred
and joined in order of cost, the default configuration ringed, and the baselines of a compare
sweep (another ``algo`` than LAC) in a colour of their own per algorithm. ``frontier_html`` is the
same figure in plotly, with the configuration, its intervals, seeds and feasible fraction on hover;
it embeds plotly.js (about 4.7 MB) because MLflow shows an artifact offline, with no CDN.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.text import Text  # noqa: E402

from lac_rllib.algorithms.registry import DEFAULT_ALGO
from sweeps.reports.configurations import fmt_value as _fmt_value  # noqa: E402
from sweeps.reports.configurations import is_na as _is_na  # noqa: E402

LAC = DEFAULT_ALGO  # the project's algorithm (the registry's default)
LAC_COLOUR = "tab:blue"
# Baselines cycle through these (tab:blue is LAC's, tab:red the cost limit's).
BASELINE_COLOURS = ("tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan",
                    "tab:gray")
FRONTIER_COLOUR = "gold"
LABEL_ALL_UP_TO = 20  # more points than this: only the frontier, the default and the baselines are labelled
LABEL_CHARS = 32  # a label longer than this is cut (a search's label lists every sampled value)


def _num(points: pd.DataFrame, col: str) -> np.ndarray:
    return (pd.to_numeric(points[col], errors="coerce").to_numpy(float) if col in points
            else np.full(len(points), np.nan))


def _non_dominated(ret: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Mask of the points no other point dominates (return >= and cost <=, one strictly); all finite."""
    geq = ret[None, :] >= ret[:, None]  # [i, j]: j's return is at least i's
    leq = cost[None, :] <= cost[:, None]
    strict = (ret[None, :] > ret[:, None]) | (cost[None, :] < cost[:, None])
    return ~(geq & leq & strict).any(axis=1)


def _feasible(points: pd.DataFrame) -> np.ndarray:
    """The summary's verdict per row (its ``feasible`` column, sweeps/reports/verdicts.py)."""
    if "feasible" not in points:
        raise ValueError("frontier points need the summary's 'feasible' column (sweeps/reports/verdicts.py's rule)")
    return points["feasible"].astype(bool).to_numpy()


def frontier(points: pd.DataFrame) -> pd.Series:
    """Boolean Series on ``points.index``: feasible and non-dominated within its task (see the module
    docstring; a frame without a ``task`` column is one task)."""
    ret, cost, limit = (_num(points, c) for c in ("return_mean", "cost_mean", "cost_limit"))
    ok = np.isfinite(ret) & np.isfinite(cost) & np.isfinite(limit) & _feasible(points)
    tasks = points["task"].astype(str).to_numpy() if "task" in points else np.zeros(len(points), str)
    on = np.zeros(len(points), bool)
    for task in np.unique(tasks[ok]):
        idx = np.flatnonzero(ok & (tasks == task))
        on[idx] = _non_dominated(ret[idx], cost[idx])
    return pd.Series(on, index=points.index, name="on_frontier")


def algorithm(row: dict) -> str:
    """The algorithm a summary row ran: its ``algo`` column, else its swept value where the swept
    param is ``algo`` (a compare sweep), else LAC."""
    if not _is_na(row.get("algo")) and str(row.get("algo", "")):
        return str(row["algo"])
    if str(row.get("param", "")) == "algo" and not _is_na(row.get("value")):
        return str(row["value"])
    return LAC


def label(row: dict) -> str:
    """Short text of a configuration: ``group param=value`` (two groups may sweep the same field: the
    ablation's NI and VT), else its group, else its ``config`` label, cut to LABEL_CHARS."""
    param = "" if _is_na(row.get("param")) else str(row.get("param", ""))
    group = "" if _is_na(row.get("group")) else str(row.get("group", ""))
    text = (f"{group} {param}={_fmt_value(row.get('value'))}".strip() if param else
            group if group and group not in ("search", "paper") else str(row.get("config") or group or "–"))
    return text if len(text) <= LABEL_CHARS else text[:LABEL_CHARS - 1] + "…"


def _prepared(summary: pd.DataFrame) -> pd.DataFrame:
    """The plottable rows (finite return and cost) with ``on_frontier``, ``algo``, ``label`` and the
    error-bar lengths (NaN where an interval is missing)."""
    df = summary.copy()
    df["on_frontier"] = frontier(df)
    df["algo_"] = [algorithm(r) for r in df.to_dict("records")]
    df["label_"] = [label(r) for r in df.to_dict("records")]
    if "task" not in df:
        df["task"] = ""
    for name in ("return", "cost"):
        point = _num(df, f"{name}_mean")
        lo, hi = _num(df, f"{name}_mean_ci_low"), _num(df, f"{name}_mean_ci_high")
        df[f"{name}_minus"] = np.clip(point - lo, 0, None)  # NaN stays NaN: no bar
        df[f"{name}_plus"] = np.clip(hi - point, 0, None)
    keep = np.isfinite(_num(df, "return_mean")) & np.isfinite(_num(df, "cost_mean"))
    return df[keep]


def _colours(df: pd.DataFrame) -> dict[str, str]:
    """LAC's colour and one per baseline algorithm, in order of appearance."""
    baselines = [a for a in dict.fromkeys(df["algo_"]) if a != LAC]
    return {LAC: LAC_COLOUR, **{a: BASELINE_COLOURS[i % len(BASELINE_COLOURS)] for i, a in enumerate(baselines)}}


def _limit(g: pd.DataFrame) -> float:
    v = pd.to_numeric(g["cost_limit"], errors="coerce").median() if "cost_limit" in g else math.nan
    return math.nan if _is_na(v) else float(v)


def _is_default(g: pd.DataFrame) -> np.ndarray:
    return g["is_default"].fillna(False).astype(bool).to_numpy() if "is_default" in g else np.zeros(len(g), bool)


def frontier_png(summary: pd.DataFrame, path) -> str | None:
    """The frontier plot (module docstring) as PNG, one panel per task; None when no configuration
    has a finite return and cost."""
    df = _prepared(summary)
    if df.empty:
        return None
    colours = _colours(df)
    tasks = list(dict.fromkeys(df["task"].astype(str)))
    fig, axes = plt.subplots(1, len(tasks), figsize=(6.4 * len(tasks), 5.2), squeeze=False)
    labels = []  # (axis, its labelled points)
    for ax, task in zip(axes[0], tasks):
        g = df[df["task"].astype(str) == task]
        cost, ret = g["cost_mean"].to_numpy(float), g["return_mean"].to_numpy(float)
        for axis, name in (("x", "cost"), ("y", "return")):  # bars only where the interval exists
            err = np.vstack([g[f"{name}_minus"], g[f"{name}_plus"]])
            has = np.isfinite(err).all(0)
            if has.any():
                ax.errorbar(cost[has], ret[has], fmt="none", ecolor="0.55", elinewidth=1, capsize=3,
                            **{f"{axis}err": err[:, has]})
        feasible = _feasible(g)
        for algo, colour in colours.items():
            m = (g["algo_"] == algo).to_numpy()
            if not m.any():
                continue
            name = "LAC configurations" if algo == LAC else algo
            filled = (m & feasible).any()  # one legend entry per algorithm, filled or hollow
            ax.scatter(cost[m & feasible], ret[m & feasible], color=colour, s=36, zorder=3,
                       label=name if filled else None)
            ax.scatter(cost[m & ~feasible], ret[m & ~feasible], facecolors="none", edgecolors=colour, s=36,
                       zorder=3, label=None if filled else name)
        if (~feasible).any():
            ax.scatter([], [], facecolors="none", edgecolors="0.4", s=36, label="hollow: mean cost over the limit")
        on = g["on_frontier"].to_numpy(bool)
        if on.any():
            order = np.argsort(cost[on], kind="stable")
            ax.plot(cost[on][order], ret[on][order], "-", color=FRONTIER_COLOUR, lw=1.5, zorder=2)
            ax.scatter(cost[on], ret[on], marker="*", s=220, color=FRONTIER_COLOUR, edgecolors="black",
                       linewidths=0.7, zorder=4, label="frontier (feasible, non-dominated)")
        default = _is_default(g)
        if default.any():
            ax.scatter(cost[default], ret[default], marker="o", s=260, facecolors="none", edgecolors="black",
                       linewidths=1.6, zorder=5, label="default")
        limit = _limit(g)
        if not math.isnan(limit):
            ax.axvline(limit, ls="--", color="tab:red", label=f"cost limit ({limit:g})")
        show = np.ones(len(g), bool) if len(g) <= LABEL_ALL_UP_TO else (on | default | (g["algo_"] != LAC).to_numpy())
        ax.margins(x=0.25, y=0.08)  # room for the labels of the right-most points
        labels.append((ax, list(zip(cost[show], ret[show], g["label_"].to_numpy()[show]))))
        ax.set(title=f"{task}: final return vs cost (mean, 95% CI)" if task else "final return vs cost (mean, 95% CI)",
               xlabel="final episode cost", ylabel="final episode return")
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    for ax, points in labels:  # after the layout: the labels are placed where they will be drawn
        place_labels(ax, points)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def place_labels(ax, points: list[tuple[float, float, str]], fontsize: int = 7) -> list:
    """Annotate each (x, y, text) beside its point, no two labels overlapping: each label starts at
    (5, 4) points from its point; going up the plot, a label whose text would overlap one already
    placed beside it (their x-ranges meet) moves up just past it, with a thin leader to its point.
    The labels keep their points' vertical order, so leaders do not cross. Configurations with the
    same mean (an ablation's NI and PR rows at one return) would otherwise print over each other."""
    renderer = ax.figure.canvas.get_renderer()
    to_points = 72.0 / ax.figure.dpi
    boxes = []
    for x, y, text in points:  # where each label would be at (5, 4): its text's box in display pixels
        trial = ax.annotate(text, (x, y), textcoords="offset points", xytext=(5, 4), fontsize=fontsize)
        boxes.append(label_box(trial, renderer))
        trial.remove()
    placed, annotations = [], {}  # placed: (x0, x1, top) of the labels so far
    for i in sorted(range(len(points)), key=lambda i: (boxes[i].y0, boxes[i].x0)):
        box, gap = boxes[i], 1.0  # pixels between two labels
        bottom = max([box.y0, *(top + gap for x0, x1, top in placed if x0 < box.x1 and box.x0 < x1)])
        x, y, text = points[i]
        moved = bottom > box.y0
        annotations[i] = ax.annotate(text, (x, y), textcoords="offset points", fontsize=fontsize,
                                     xytext=(5, 4 + (bottom - box.y0) * to_points),
                                     arrowprops=dict(arrowstyle="-", lw=0.4, color="0.5") if moved else None)
        placed.append((box.x0, box.x1, bottom + box.height))
    return [annotations[i] for i in range(len(points))]


def label_box(annotation, renderer):
    """The display box of an annotation's text alone (an Annotation's own extent includes its
    leader, which starts at the point every label of that point shares)."""
    annotation.update_positions(renderer)  # where the text goes, from its point and offset
    return Text.get_window_extent(annotation, renderer)


def _hover(r: dict) -> str:
    def ci(name):
        lo, hi = r.get(f"{name}_mean_ci_low"), r.get(f"{name}_mean_ci_high")
        bounds = "[–]" if _is_na(lo) or _is_na(hi) else f"[{float(lo):.2f}, {float(hi):.2f}]"
        return f"{float(r[f'{name}_mean']):.2f} {bounds}"

    ff = r.get("feasible_fraction")
    lines = [f"<b>{r['label_']}</b>", str(r.get("config") or ""), f"group {r.get('group', '')} · {r['algo_']}",
             f"return {ci('return')}", f"cost {ci('cost')} (limit {_fmt_value(r.get('cost_limit'))})",
             f"seeds {r.get('n_seeds', '–')}", f"feasible seeds {'–' if _is_na(ff) else f'{float(ff):.0%}'}"]
    if r.get("on_frontier"):
        lines.append("on the frontier")
    if r.get("is_default"):
        lines.append("default configuration")
    return "<br>".join(x for x in lines if x)


def frontier_figure(summary: pd.DataFrame):
    """The frontier plot as a plotly Figure (None when nothing is plottable)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    df = _prepared(summary)
    if df.empty:
        return None
    colours = {a: matplotlib.colors.to_hex(c) for a, c in _colours(df).items()}  # plotly takes CSS colours
    tasks = list(dict.fromkeys(df["task"].astype(str)))
    fig = make_subplots(rows=1, cols=len(tasks), subplot_titles=[t or "all" for t in tasks])
    shown: set[str] = set()

    def legend(name):
        first = name not in shown
        shown.add(name)
        return dict(name=name, legendgroup=name, showlegend=first)

    def bars(g, name):
        return dict(type="data", symmetric=False, array=g[f"{name}_plus"].tolist(),
                    arrayminus=g[f"{name}_minus"].tolist(), color="rgba(120,120,120,0.7)", thickness=1)

    for col, task in enumerate(tasks, start=1):
        g = df[df["task"].astype(str) == task]
        for algo, colour in colours.items():
            s = g[g["algo_"] == algo]
            if s.empty:
                continue
            feasible = _feasible(s)
            fig.add_trace(go.Scatter(
                x=s["cost_mean"], y=s["return_mean"], mode="markers", error_x=bars(s, "cost"),
                error_y=bars(s, "return"), hovertext=[_hover(r) for r in s.to_dict("records")], hoverinfo="text",
                marker=dict(color=[colour if f else "white" for f in feasible], line=dict(color=colour, width=1.5),
                            size=9), **legend("LAC configurations" if algo == LAC else algo)), row=1, col=col)
        on = g[g["on_frontier"]].sort_values("cost_mean", kind="stable")
        if len(on):
            fig.add_trace(go.Scatter(
                x=on["cost_mean"], y=on["return_mean"], mode="lines+markers+text", text=on["label_"],
                textposition="top center", hovertext=[_hover(r) for r in on.to_dict("records")], hoverinfo="text",
                line=dict(color=FRONTIER_COLOUR), marker=dict(symbol="star", size=16, color=FRONTIER_COLOUR,
                                                              line=dict(color="black", width=1)),
                **legend("frontier (feasible, non-dominated)")), row=1, col=col)
        d = g[_is_default(g)]
        if len(d):
            fig.add_trace(go.Scatter(
                x=d["cost_mean"], y=d["return_mean"], mode="markers",
                hovertext=[_hover(r) for r in d.to_dict("records")], hoverinfo="text",
                marker=dict(symbol="circle-open", size=20, color="black", line=dict(width=2)),
                **legend("default")), row=1, col=col)
        limit = _limit(g)
        if not math.isnan(limit):
            fig.add_vline(x=limit, line_dash="dash", line_color="red", annotation_text=f"cost limit {limit:g}",
                          row=1, col=col)
        fig.update_xaxes(title_text="final episode cost", row=1, col=col)
        fig.update_yaxes(title_text="final episode return", row=1, col=col)
    fig.update_layout(title="Final return vs cost per configuration (mean, 95% interval); hollow: infeasible",
                      template="plotly_white", width=max(700, 620 * len(tasks)), height=560)
    return fig


def frontier_html(summary: pd.DataFrame, path) -> str | None:
    """The interactive frontier plot as a self-contained HTML file (plotly.js embedded); None when
    nothing is plottable."""
    fig = frontier_figure(summary)
    if fig is None:
        return None
    fig.write_html(str(path), include_plotlyjs=True, full_html=True)
    return str(path)
