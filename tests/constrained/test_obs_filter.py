"""The observation filter (docs/spec.md §5): RLlib's running mean/std with the std floored before dividing."""

import gymnasium as gym
import numpy as np
import pytest

from lac_rllib.constrained.obs_filter import FlooredMeanStdFilter


def _normalised_last(std_floor: float):
    """Push 200 observations whose dim 0 is N(0, 1) and dim 1 is 0.5 + 1e-6 noise; filter a new one."""
    space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    conn = FlooredMeanStdFilter(clip_by_value=5.0, std_floor=std_floor)
    conn.input_observation_space = space  # as a pipeline sets it (RLlib's ctor cannot take it)
    conn._init_new_filters()
    f = conn._filters[None]
    rng = np.random.default_rng(0)
    for _ in range(200):
        f(np.array([rng.normal(), 0.5 + 1e-6 * rng.normal()]))
    return f(np.array([1.0, 0.5 + 3e-6]), update=False), f


def test_tiny_variance_dimension_is_not_blown_up():
    x, f = _normalised_last(1e-2)
    rs = f.running_stats
    assert abs(x[1]) < 1e-3  # (3e-6 − mean) / 1e-2, not (3e-6 − mean) / 1e-6
    assert x[0] == pytest.approx((1.0 - rs.mean[0]) / rs.std[0], rel=1e-5)  # ordinary dims as RLlib
    stock, _ = _normalised_last(0.0)  # floor off: RLlib's std + 1e-8
    assert abs(stock[1]) > 1.0


def test_floor_survives_the_checkpoint_kwargs():
    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    conn = FlooredMeanStdFilter(clip_by_value=5.0, std_floor=0.05)
    _, kwargs = conn.get_ctor_args_and_kwargs()
    rebuilt = FlooredMeanStdFilter(**kwargs)
    rebuilt.input_observation_space = space
    rebuilt._init_new_filters()
    assert rebuilt.std_floor == 0.05 and rebuilt._filters[None].std_floor == 0.05 and rebuilt.clip_by_value == 5.0
