"""Tests for sweeps/reports/frontier.py: the frontier's logic on hand-made points, then its two plots."""

import math

import matplotlib.image as mpimg
import numpy as np
import pandas as pd

from sweeps.reports import frontier

NAN = math.nan


def _point(name, ret, cost, limit=10.0, task="T", **kw):
    return dict(name=name, group="g", param="langevin_steps", value=name, task=task, config=f"g-{name}",
                return_mean=ret, cost_mean=cost, cost_limit=limit, feasible=cost <= limit, **kw)


# (name, return, cost): on the frontier or not, and why. Limit 10.
POINTS = [
    _point("A", 10.0, 5.0),  # on: nothing feasible has return >= 10 at cost <= 5
    _point("B", 8.0, 6.0),  # off: A has more return at less cost
    _point("C", 12.0, 9.0),  # on: more return than A, for more cost
    _point("D", 12.0, 9.0),  # on: C's twin; ties do not dominate each other
    _point("E", 10.0, 7.0),  # off: A has the same return at less cost (weakly dominated)
    _point("F", 9.0, 5.0),  # off: A has more return at the same cost
    _point("G", 13.0, 10.0),  # on: cost == limit is feasible
    _point("H", 30.0, 10.5),  # off: over the limit (it would top every return)
    _point("I", NAN, 1.0),  # off: no return
    _point("J", 50.0, NAN),  # off: no cost
    _point("K", 50.0, 1.0, limit=NAN),  # off: no limit, feasibility unknown
    _point("L", 1.0, 8.0, task="U"),  # on: alone on its task, A (task T) does not dominate it
    _point("M", 0.5, 9.0, task="U"),  # off: L dominates it
]
ON = {"A", "C", "D", "G", "L"}


def test_frontier_keeps_feasible_non_dominated_points_and_ties():
    pts = pd.DataFrame(POINTS).set_index("name", drop=False)
    on = frontier.frontier(pts)
    assert on.dtype == bool and list(on.index) == list(pts.index)
    assert set(on[on].index) == ON


def test_frontier_is_order_free_and_needs_no_task_column():
    pts = pd.DataFrame(POINTS).set_index("name", drop=False)
    shuffled = pts.sample(frac=1.0, random_state=0)
    assert set(frontier.frontier(shuffled)[lambda s: s].index) == ON
    one_task = pts[pts["task"] == "T"].drop(columns="task")
    assert set(frontier.frontier(one_task)[lambda s: s].index) == ON - {"L"}
    assert not frontier.frontier(pts.iloc[:0]).any()


def _summary():
    """Two tasks, LAC configurations with intervals (one without), the default, two baselines."""
    rows = []
    rng = np.random.default_rng(0)
    for task in ("PointGoal1", "CarGoal1"):
        for i, v in enumerate([10, 20, 40, 80]):
            ret, cost = 5.0 + 3 * i, 8.0 + 6 * i
            rows.append(dict(group="VT", param="langevin_steps", value=v, task=task, config=f"VT-langevin_steps={v}",
                             n_seeds=3, return_mean=ret, cost_mean=cost, cost_limit=25.0,
                             return_mean_ci_low=ret - rng.uniform(0.5, 2), return_mean_ci_high=ret + 1.0,
                             cost_mean_ci_low=NAN if i == 0 else cost - 2,  # no cost bar on the first
                             cost_mean_ci_high=NAN if i == 0 else cost + 3,
                             feasible_fraction=1.0 if cost <= 25 else 0.0, feasible=cost <= 25, is_default=v == 20))
        for algo, ret, cost in (("lac", 8.0, 14.0), ("ppo_lag", 4.0, 30.0), ("sac_lag", 9.0, 20.0)):
            rows.append(dict(group="compare", param="algo", value=algo, task=task, config=f"compare-algo={algo}",
                             n_seeds=3, return_mean=ret, cost_mean=cost, cost_limit=25.0, return_mean_ci_low=ret - 1,
                             return_mean_ci_high=ret + 1, cost_mean_ci_low=cost - 1, cost_mean_ci_high=cost + 1,
                             feasible_fraction=2 / 3, feasible=cost <= 25, is_default=False))
    rows.append(dict(group="VT", param="langevin_steps", value=160, task="PointGoal1", n_seeds=0,
                     return_mean=NAN, cost_mean=NAN, cost_limit=25.0, feasible=False, is_default=False))  # all failed
    return pd.DataFrame(rows)


def test_baselines_get_their_own_colour_and_legend_entry():
    s = _summary()
    assert [frontier.algorithm(r) for r in s.to_dict("records")][-4:] == ["lac", "ppo_lag", "sac_lag", "lac"]
    assert frontier.algorithm({"algo": "ppo_lag", "param": "beta", "value": 1.0}) == "ppo_lag"
    fig = frontier.frontier_figure(s)
    colour = {t.name: t.marker.line.color for t in fig.data if t.name in ("LAC configurations", "ppo_lag", "sac_lag")}
    assert len(set(colour.values())) == 3, colour
    legend = [t.name for t in fig.data if t.showlegend]
    assert legend.count("ppo_lag") == legend.count("sac_lag") == 1  # one entry though two panels


def test_frontier_png_is_one_panel_per_task(tmp_path):
    path = frontier.frontier_png(_summary(), tmp_path / "frontier.png")
    img = mpimg.imread(path)
    assert img.shape == (round(5.2 * 110), round(2 * 6.4 * 110), 4)  # figsize × dpi, two tasks side by side
    assert frontier.frontier_png(_summary().iloc[-1:], tmp_path / "none.png") is None


def test_frontier_html_embeds_plotly_and_names_configurations(tmp_path):
    path = frontier.frontier_html(_summary(), tmp_path / "frontier.html")
    html = open(path, encoding="utf-8").read()
    assert "plotly" in html and 'src="https://cdn.plot.ly' not in html  # plotly.js embedded: MLflow is offline
    for text in ("langevin_steps=10", "langevin_steps=80", "algo=ppo_lag", "default configuration", "on the frontier"):
        assert text in html, text


def test_labels_of_points_at_the_same_place_do_not_overlap():
    """docs/sweeps-default/frontier.png printed 'NI langevin_steps=20' over 'PR beta=0.5' (both at
    return −5.1): every label now gets its own place, the first beside its point."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.scatter([0.0, 0.0, 0.0, 0.3], [-5.1, -5.1, -5.1, -5.0])
    points = [(0.0, -5.1, "NI langevin_steps=20"), (0.0, -5.1, "PR beta=0.5"), (0.0, -5.1, "VT langevin_steps=10"),
              (0.3, -5.0, "default configuration")]
    annotations = frontier.place_labels(ax, points)
    renderer = fig.canvas.get_renderer()
    boxes = [frontier.label_box(a, renderer) for a in annotations]
    assert sorted(a.get_text() for a in annotations) == sorted(p[2] for p in points)
    assert not any(boxes[i].overlaps(boxes[j]) for i in range(len(boxes)) for j in range(i))
    assert [a.get_text() for a in annotations] == [p[2] for p in points]  # in the order given
    assert sum(a.xyann == (5, 4) for a in annotations[:3]) == 1  # of three at one place, one stays beside it
    plt.close(fig)
