"""sweeps/reports/stats.py against values computed here independently (plain numpy resampling, pair counts)."""

import math

import numpy as np
import pytest

from sweeps.reports import stats

SCORES = np.array([1.0, 2.0, 3.0, 4.0, 10.0])  # skewed: the mean's interval is not symmetric


def _numpy_percentile_ci(x, func, reps=50_000, seed=123):
    idx = np.random.default_rng(seed).integers(0, len(x), size=(reps, len(x)))
    boot = np.array([func(x[i]) for i in idx])
    return np.percentile(boot, [2.5, 97.5])


def _iqm(x):
    x = np.sort(x)
    k = len(x) // 4  # 25% cut from each end
    return x[k:len(x) - k].mean()


@pytest.mark.parametrize("aggregate,func", [("mean", np.mean), ("iqm", _iqm)])
def test_interval_matches_an_independent_bootstrap(monkeypatch, aggregate, func):
    monkeypatch.setattr(stats, "REPS", 20_000)  # Monte Carlo error of each end ≈ 0.03 here
    point, lo, hi = stats.interval(SCORES, aggregate)
    ref_lo, ref_hi = _numpy_percentile_ci(SCORES, func)
    assert point == pytest.approx(func(SCORES))
    # A 90% interval or a normal approximation would be off by 0.3-1.0 at either end here.
    assert lo == pytest.approx(ref_lo, abs=0.12) and hi == pytest.approx(ref_hi, abs=0.12), (lo, hi, ref_lo, ref_hi)


def test_interval_is_seeded_and_needs_two_seeds():
    assert stats.interval(SCORES) == stats.interval(SCORES)
    point, lo, hi = stats.interval([3.0])
    assert point == 3.0 and math.isnan(lo) and math.isnan(hi)
    assert stats.interval([2.0, 2.0, 2.0]) == (2.0, 2.0, 2.0)
    assert all(math.isnan(v) for v in stats.interval([math.nan]))


def test_probability_of_improvement_counts_pairs_with_half_ties():
    x, y = np.array([1.0, 2.0, 3.0, 5.0]), np.array([2.0, 2.0, 0.0])
    wins = sum((a > b) + 0.5 * (a == b) for a in x for b in y) / (len(x) * len(y))
    assert stats.probability_of_improvement(x, y) == pytest.approx(wins)
    lower = sum((a < b) + 0.5 * (a == b) for a in x for b in y) / (len(x) * len(y))
    assert stats.probability_of_improvement(x, y, lower_is_better=True) == pytest.approx(lower)
    assert stats.probability_of_improvement(x, x) == 0.5
    assert math.isnan(stats.probability_of_improvement(x, []))


def test_the_seeds_line_warns_under_five():
    assert "Warning" in stats.seeds_line([3, 3]) and "over 3 seeds" in stats.seeds_line([3, 3])
    assert "Warning" not in stats.seeds_line([5, 6]) and "over 5-6 seeds" in stats.seeds_line([5, 6])
