"""Tests for sweeps/reports/safety.py (Wilson interval, violation, the per-configuration table) and
sweeps/reports/chain_health.py (the chain flags), on hand-made numbers."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from sweeps.reports import chain_health, safety, verdicts

NAN = math.nan


@pytest.mark.parametrize("k,n", [(0, 1), (1, 1), (0, 3), (1, 3), (2, 3), (3, 3), (0, 10), (4, 10), (10, 10),
                                 (7, 20), (1, 2)])
def test_wilson_interval_matches_scipy(k, n):
    p, lo, hi = verdicts.proportion_interval(k, n)
    ref = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert p == k / n
    assert lo == pytest.approx(ref.low, abs=1e-12) and hi == pytest.approx(ref.high, abs=1e-12)
    assert 0.0 <= lo <= p <= hi <= 1.0


def test_wilson_interval_without_trials():
    assert all(math.isnan(x) for x in verdicts.proportion_interval(0, 0))
    with pytest.raises(ValueError):
        verdicts.proportion_interval(4, 3)


def curve(costs, limit=25.0, steps=None):
    steps = steps if steps is not None else [1000.0 * (i + 1) for i in range(len(costs))]
    return pd.DataFrame(dict(env_steps=steps, episode_return=0.0, episode_cost=costs, cost_limit=limit))


def test_violation_sums_the_excess_and_finds_the_worst_iteration():
    # excess over 25: -5, +5, (NaN, left out), +2, -1, +5 (a later tie: the first is the worst)
    v = safety.violation(curve([20.0, 30.0, NAN, 27.0, 24.0, 30.0]))
    assert v["violation_total"] == pytest.approx(5 + 2 + 5)
    assert v["n_iterations"] == 5 and v["violating_iterations"] == 3
    assert v["violation_mean"] == pytest.approx(12 / 5)
    assert v["worst_excess"] == pytest.approx(5.0) and v["worst_env_steps"] == 2000.0


def test_training_time_safety_on_a_hand_made_curve():
    """Eckel et al. (2024): the env steps to the first feasible iteration and the longest run of
    infeasible ones (cost rate: the trial's own metric, averaged in the safety table)."""
    v = safety.violation(curve([30.0, 40.0, 20.0, 26.0, 27.0, 28.0, 10.0, 30.0]))  # limit 25
    assert v["steps_to_feasible"] == 3000.0  # the third iteration is the first within the limit
    assert v["longest_infeasible"] == 3  # 26, 27, 28 in a row (30, 40 before: 2; 30 at the end: 1)
    never = safety.violation(curve([26.0, 30.0]))
    assert math.isnan(never["steps_to_feasible"]) and never["longest_infeasible"] == 2
    always = safety.violation(curve([1.0, 2.0]))
    assert always["steps_to_feasible"] == 1000.0 and always["longest_infeasible"] == 0


def test_violation_of_a_safe_run_and_of_no_run():
    v = safety.violation(curve([10.0, 20.0, 15.0]))
    assert v["violation_total"] == 0.0 and v["violation_mean"] == 0.0 and v["violating_iterations"] == 0
    assert v["worst_excess"] == pytest.approx(-5.0) and v["worst_env_steps"] == 2000.0
    for empty in (curve([NAN, NAN]), curve([]), None, pd.DataFrame({"env_steps": [1.0]})):
        e = safety.violation(empty)
        assert math.isnan(e["violation_total"]) and math.isnan(e["worst_excess"]) and e["n_iterations"] == 0


def _trial(tid, value, seed, cost, status="TERMINATED", ret=1.0, limit=25.0):
    return dict(trial_id=tid, group="VT", param="langevin_steps", value=value, task="PointGoal1",
                config=f"VT-langevin_steps={value}", seed=seed, status=status, episode_return=ret,
                episode_cost=cost, cost_limit=limit, feasible=float(cost <= limit), objective=ret,
                cost_rate=cost / 1000)


def test_safety_table_per_configuration():
    trials = pd.DataFrame([
        _trial("a0", 10, 0, 20.0), _trial("a1", 10, 1, 24.0), _trial("a2", 10, 2, 30.0),
        _trial("a3", 10, 3, 0.0, status="ERROR"), _trial("a4", 10, 4, 0.0, status="STOPPED"),
        _trial("a5", 10, 5, 1.0, ret=NAN),  # no final return: failed
        _trial("b0", 20, 0, 26.0),  # one seed, no curve
    ])
    curves = {"a0": curve([40.0, 20.0]),  # excess +15, -5: total 15, worst 15 at 1000
              "a1": curve([28.0, 35.0, 24.0]),  # +3, +10, -1: total 13, worst 10 at 2000
              "a2": curve([26.0, 30.0]).drop(columns="cost_limit"),  # the trial's limit: +1, +5: total 6
              "a3": curve([500.0]), "a4": curve([500.0])}  # failed and stopped: not counted
    t = safety.safety_table(trials, curves)
    assert list(t.columns) == safety.KEYS + safety.SAFETY_COLUMNS and list(t["value"]) == [10, 20]
    a = t.iloc[0]
    assert (a["n_seeds"], a["n_feasible"]) == (3, 2)
    wilson = verdicts.proportion_interval(2, 3)
    assert (a["p_feasible"], a["p_feasible_low"], a["p_feasible_high"]) == pytest.approx(wilson)
    assert a["violation_total"] == pytest.approx((15 + 13 + 6) / 3)
    assert a["violation_mean"] == pytest.approx((15 / 2 + 13 / 3 + 6 / 2) / 3)
    assert (a["worst_excess"], a["worst_env_steps"], a["worst_trial_id"]) == (15.0, 1000.0, "a0")
    assert a["final_cost_std"] == pytest.approx(np.std([20, 24, 30], ddof=1))
    assert (a["final_cost_min"], a["final_cost_max"]) == (20.0, 30.0)
    # a0 feasible at 2000, a1 at 3000, a2 never: the mean over the seeds that got there, one never
    assert (a["steps_to_feasible"], a["never_feasible"], a["longest_infeasible"]) == (2500.0, 1, 2)
    assert a["cost_rate"] == pytest.approx(np.mean([0.02, 0.024, 0.03]))
    b = t.iloc[1]
    assert (b["n_seeds"], b["n_feasible"], b["p_feasible"]) == (1, 0, 0.0)
    assert math.isnan(b["violation_total"]) and math.isnan(b["final_cost_std"]) and pd.isna(b["worst_trial_id"])


def _health(value, at_bound, clip, std, seed=0, param="langevin_steps"):
    return dict(group="g", param=param, value=value, task="T", config=f"g-{value}", trial_id=f"{value}-{seed}",
                langevin_at_bound=at_bound, langevin_clip_fraction=clip, actor_std_mean=std)


def test_chain_flags_appear_exactly_past_their_thresholds():
    rows = pd.DataFrame([
        _health("healthy", 0.05, 0.5, 0.3),
        _health("edge", chain_health.AT_BOUND_MAX, 0.989, chain_health.STD_COLLAPSED),  # on the thresholds: none
        _health("bound", 0.05, 0.5, 0.3), _health("bound", 0.20, 0.5, 0.3, seed=1),  # mean 0.125 > 0.10
        _health("clip", 0.05, chain_health.CLIP_EVERY_STEP, 0.3),
        _health("sigma", 0.05, 0.5, 0.049),
        _health("all", 0.5, 1.0, 0.01),
        _health("ppo_lag", NAN, NAN, NAN, param="algo"),
    ])
    f = chain_health.chain_flags(rows)
    assert list(f.index.names) == chain_health.KEYS and f.name == "chain_flags"
    by_value = dict(zip(f.index.get_level_values("value"), f))
    assert by_value == {
        "healthy": "", "edge": "", "bound": "end points on the bound (12%)", "clip": "clip binds every step",
        "sigma": "σ collapsed (σ=0.049)", "ppo_lag": "",
        "all": "end points on the bound (50%); clip binds every step; σ collapsed (σ=0.01)"}


def test_chain_flags_without_the_columns():
    rows = pd.DataFrame([dict(group="compare", param="algo", value="ppo_lag", task="T", config="c")])
    assert list(chain_health.chain_flags(rows)) == [""]
