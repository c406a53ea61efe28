"""Tests for sweeps/reports/importance.py on synthetic sweeps whose deciding field is known."""

import math

import numpy as np
import pandas as pd
import pytest
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

from sweeps.reports import importance

NAN = math.nan


def _trial(tid, config, seed, ret, cost, status="TERMINATED", task="PointGoal1", **fields):
    return dict(trial_id=tid, group="search", param="", value=None, task=task, config=config, seed=seed,
                status=status, episode_return=ret, episode_cost=cost, cost_limit=25.0, feasible=float(cost <= 25),
                objective=ret, **fields)


def grid(seed=0):
    """5 × 5 grid, 2 seeds: langevin_steps decides the return, beta the cost; each is noise to the other."""
    rng = np.random.default_rng(seed)
    rows = []
    for steps in (1, 3, 10, 30, 100):
        for beta in (0.0, 1.0, 2.0, 3.0, 4.0):
            for s in range(2):
                rows.append(_trial(f"{steps}-{beta}-{s}", f"T={steps}-beta={beta}", s,
                                   ret=10 * math.log10(steps) + rng.normal(0, 0.5),
                                   cost=8 * beta + rng.normal(0, 0.5),
                                   langevin_steps=str(steps), beta=str(beta)))  # MLflow params are text
    return pd.DataFrame(rows)


def search(seed=1, n=30):
    """30 sampled configurations, 1-2 seeds: the step size (log-uniform) decides the return, the
    start (categorical) the cost, temperature is noise to both."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        eta, start, temp = 10 ** rng.uniform(-5, -2), rng.choice(["informative", "noninformative"]), rng.uniform(0, 1)
        for s in range(1 + i % 2):
            rows.append(_trial(f"c{i}-{s}", f"search-{i}", s, ret=-3 * math.log10(eta) + rng.normal(0, 0.3),
                               cost=(30.0 if start == "noninformative" else 10.0) + rng.normal(0, 1.0),
                               langevin_step_size=eta, langevin_start=start, temperature=temp))
    return pd.DataFrame(rows)


@pytest.mark.parametrize("make,fields,ret_field,cost_field", [
    (grid, ["langevin_steps", "beta"], "langevin_steps", "beta"),
    (search, ["langevin_step_size", "langevin_start", "temperature"], "langevin_step_size", "langevin_start")])
def test_the_deciding_field_ranks_first(make, fields, ret_field, cost_field):
    imp = importance.importances(make(), fields)
    assert set(imp) == {"return", "cost"} and imp.reason == ""
    assert importance.top_fields(imp["return"], 1)[0][0] == ret_field, imp
    assert importance.top_fields(imp["cost"], 1)[0][0] == cost_field, imp
    assert imp["return"][ret_field] > 0.8 and imp["cost"][cost_field] > 0.8, imp
    for d in imp.values():
        assert sum(d.values()) == pytest.approx(1.0)


def test_importances_are_seeded():
    assert importance.importances(search(), ["langevin_step_size", "temperature"]) == \
        importance.importances(search(), ["langevin_step_size", "temperature"])


def test_study_has_one_trial_per_configuration_with_inferred_distributions():
    t = grid()
    t["flag"] = [bool(i % 4 < 2) for i in range(len(t))]  # the same for both seeds of a configuration
    t["mode"] = "batch"  # one value: dropped
    t["lr"] = [1e-4, 1e-4, 3e-4, 3e-4] * 12 + [1e-4, 1e-4]  # positive, max/min < 100: linear
    t = pd.concat([t, pd.DataFrame([
        _trial("err", "T=1-beta=0.0", 7, 999.0, 0.0, status="ERROR", langevin_steps="1", beta="0.0"),
        _trial("nan", "T=1-beta=0.0", 8, NAN, 0.0, langevin_steps="1", beta="0.0"),
        _trial("asha", "T=1-beta=0.0", 9, 999.0, 0.0, status="STOPPED", langevin_steps="1", beta="0.0")])])
    study = importance.study_from_trials(t, ["langevin_steps", "beta", "flag", "mode", "lr", "absent"], "return")
    assert len(study.trials) == 25 and study.direction.name == "MAXIMIZE"
    d = study.trials[0].distributions
    assert d["langevin_steps"] == IntDistribution(1, 100, log=True)  # max/min = 100
    assert d["beta"] == FloatDistribution(0.0, 4.0)  # includes 0: linear
    assert d["lr"] == FloatDistribution(1e-4, 3e-4)
    assert d["flag"] == CategoricalDistribution([False, True])
    assert set(study.user_attrs["dropped"]) == {"mode", "absent"}
    first = [tr for tr in study.trials if tr.user_attrs["config"] == "T=1-beta=0.0"][0]
    seeds = t[(t["config"] == "T=1-beta=0.0") & (t["status"] == "TERMINATED") & t["episode_return"].notna()]
    assert len(seeds) == 2 and first.value == pytest.approx(seeds["episode_return"].mean())  # the 999s left out
    assert importance.study_from_trials(t, ["beta"], "episode_cost").direction.name == "MINIMIZE"


def test_categorical_fields_from_text_and_log_floats():
    study = importance.study_from_trials(search(), ["langevin_step_size", "langevin_start"], "cost")
    d = study.trials[0].distributions
    assert isinstance(d["langevin_step_size"], FloatDistribution) and d["langevin_step_size"].log
    assert d["langevin_start"] == CategoricalDistribution(["informative", "noninformative"])


def test_degenerate_sweeps_give_a_reason_not_an_error():
    t = grid()
    one = importance.importances(t, ["langevin_steps", "not_a_column"])
    assert one == {"return": {"langevin_steps": 1.0}, "cost": {"langevin_steps": 1.0}}
    assert "only langevin_steps varied" in one.reason
    t["same"] = 3
    none = importance.importances(t, ["same"])
    assert none == {} and "no field varied" in none.reason
    few = t[t["config"].isin(["T=1-beta=0.0", "T=3-beta=1.0", "T=10-beta=2.0", "T=30-beta=3.0"])]
    small = importance.importances(few, ["langevin_steps", "beta"])
    assert small == {} and "fewer than the 5" in small.reason
    flat = t.assign(episode_cost=5.0)
    half = importance.importances(flat, ["langevin_steps", "beta"])
    assert set(half) == {"return"} and "cost: the same value" in half.reason
    failed = t.assign(status="ERROR")
    assert importance.importances(failed, ["langevin_steps", "beta"]) == {}


def test_several_tasks_are_standardised_within_task():
    a, b = grid(), grid(seed=3)
    b["task"], b["episode_return"] = "CarGoal1", b["episode_return"] * 1000 + 5000  # another scale
    study = importance.study_from_trials(pd.concat([a, b]), ["langevin_steps", "beta"], "return")
    values = np.array([tr.value for tr in study.trials])
    assert study.user_attrs["standardized_per_task"] and len(values) == 50
    assert abs(values).max() < 3 and values[:25].mean() == pytest.approx(0.0, abs=1e-9)
    imp = importance.importances(pd.concat([a, b]), ["langevin_steps", "beta"])
    assert importance.top_fields(imp["return"], 1)[0][0] == "langevin_steps"


def test_top_fields_and_note_line():
    assert importance.top_fields({"a": 0.2, "b": 0.7, "c": 0.1, "d": 0.1}, k=3) == [("b", 0.7), ("a", 0.2), ("c", 0.1)]
    with pytest.raises(ValueError):
        importance.top_fields({"return": {"a": 1.0}})
    line = importance.importance_line(importance.importances(grid(), ["langevin_steps", "beta"]))
    assert "return: `langevin_steps`" in line and "cost: `beta`" in line


def test_importance_plots_write_html_and_png(tmp_path):
    paths = importance.importance_plots(grid(), ["langevin_steps", "beta"], tmp_path)
    assert set(paths) == set(importance.PLOT_NAMES)
    for name, path in paths.items():
        if name.endswith(".html"):
            html = open(path, encoding="utf-8").read()
            assert "plotly" in html and 'src="https://cdn.plot.ly' not in html and "langevin_steps" in html
        else:
            assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    assert importance.importance_plots(grid(), ["absent"], tmp_path / "none") == {}


def test_importance_plots_leave_matplotlib_style_alone(tmp_path):
    import matplotlib

    before = dict(matplotlib.rcParams)
    importance.importance_plots(grid(), ["langevin_steps", "beta"], tmp_path)
    assert dict(matplotlib.rcParams) == before  # optuna's ggplot would otherwise grey every later report plot


@pytest.mark.parametrize("make,fields", [(grid, ["langevin_steps", "beta"]),
                                         (search, ["langevin_step_size", "langevin_start", "temperature"])])
@pytest.mark.parametrize("missing", [False, True])
def test_the_importances_do_not_follow_the_order_the_trials_are_listed_in(make, fields, missing):
    """MLflow lists a sweep's runs in the order they finished; the forest (seeded) must see the
    configurations in one order whatever it was, or the same sweep gets different importances.
    Also when some trials lack a field (a tuned comparison's defaults beside its samples)."""
    trials = make()
    if missing:
        trials.loc[trials.index % 7 == 0, fields[-1]] = None
    listed = importance.importances(trials, fields)
    for seed in (1, 2):
        shuffled = importance.importances(trials.sample(frac=1, random_state=seed), fields)
        assert shuffled == listed, (seed, listed, shuffled)
    assert importance.importances(trials.iloc[::-1], fields) == listed
