"""Critic targets (eq. 13) and the Lagrange update (eq. 14)."""

import types

import pytest
import torch
from ray.rllib.core.columns import Columns

from lac_rllib.algorithms.lac.learner import critic_targets
from lac_rllib.constrained.costs import COSTS


def _cfg(**kw):
    base = dict(reward_scale=10.0, gamma=0.9, cost_gamma=0.8, bootstrap_on_truncation=True)
    return types.SimpleNamespace(**{**base, **kw})


def _batch(terminated, truncated):
    return {
        Columns.REWARDS: torch.tensor([1.0, 1.0, 1.0]),
        COSTS: torch.tensor([0.5, 0.5, 0.5]),
        Columns.TERMINATEDS: torch.tensor(terminated),
        Columns.TRUNCATEDS: torch.tensor(truncated),
    }


# Rows 0-1: reward critics, rows 2-3: cost critics; per sample different argmin/argmax.
Q_NEXT = torch.tensor([
    [3.0, -1.0, 5.0],
    [2.0, 4.0, 6.0],
    [7.0, 1.0, 0.0],
    [8.0, -2.0, 9.0],
])


def test_targets_use_min_reward_and_max_cost_critics():
    y_r, y_c = critic_targets(_batch([False] * 3, [False] * 3), Q_NEXT, 2, _cfg())
    torch.testing.assert_close(y_r, 10.0 + 0.9 * torch.tensor([2.0, -1.0, 5.0]))
    torch.testing.assert_close(y_c, 0.5 + 0.8 * torch.tensor([8.0, 1.0, 9.0]))


def test_terminated_cuts_bootstrap_truncated_does_not():
    y_r, y_c = critic_targets(_batch([True, False, False], [False, True, False]), Q_NEXT, 2, _cfg())
    assert y_r[0] == 10.0 and y_c[0] == 0.5  # terminated: no bootstrap
    assert y_r[1] == pytest.approx(10.0 + 0.9 * -1.0) and y_c[1] == pytest.approx(0.5 + 0.8 * 1.0)


def test_truncation_as_terminal_reproduces_authors_code():
    y_r, y_c = critic_targets(_batch([False] * 3, [False, True, False]), Q_NEXT, 2,
                              _cfg(bootstrap_on_truncation=False))
    assert y_r[1] == 10.0 and y_c[1] == 0.5
    assert y_r[0] == pytest.approx(10.0 + 0.9 * 2.0)
