"""The learner connector's row pieces (lac_rllib/constrained/costs.py): a shuffle and a draw."""

import numpy as np

from lac_rllib.constrained.costs import DrawRows, ShuffleRows


def _batch(n=1000):
    rows = np.arange(n)
    return {"m": {"obs": np.stack([rows, -rows], 1).astype(np.float32), "costs": rows * 2.0, "id": "not a column"}}


def _call(piece, batch):
    return piece(rl_module=None, batch=batch, episodes=[])


def test_drawn_rows_are_uniform_with_replacement_and_stay_aligned():
    n = 1000
    out = _call(DrawRows(rows=20 * n, seed=0), _batch(n))["m"]
    picked = out["obs"][:, 0].astype(int)
    assert len(picked) == 20 * n and out["id"] == "not a column"
    np.testing.assert_array_equal(out["obs"][:, 1], -picked)  # one index array for every column
    np.testing.assert_array_equal(out["costs"], picked * 2.0)
    # A draw of n rows with replacement holds ~(1 − 1/e)·n = 632 distinct rows (sd ≈ 8.5 here);
    # a permutation, or a cyclic pass, holds all n.
    distinct = len(np.unique(picked[:n]))
    assert 600 < distinct < 665, distinct
    # Uniform over the buffer: each row drawn 20 times on average; Pearson's χ² on 999 degrees of
    # freedom stays below 1150 (p ≈ 0.0006) unless some rows are favoured.
    counts = np.bincount(picked, minlength=n)
    chi2 = ((counts - 20) ** 2 / 20).sum()
    assert chi2 < 1150 and counts.min() > 0, chi2


def test_a_seeded_draw_repeats_and_the_shuffle_is_a_permutation():
    a, b = (_call(DrawRows(rows=500, seed=3), _batch(100))["m"]["costs"] for _ in range(2))
    np.testing.assert_array_equal(a, b)
    shuffled = _call(ShuffleRows(seed=3), _batch(100))["m"]["costs"]
    assert sorted(shuffled) == sorted(np.arange(100) * 2.0) and not np.array_equal(shuffled, np.arange(100) * 2.0)
