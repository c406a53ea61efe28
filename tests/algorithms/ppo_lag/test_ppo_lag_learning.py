"""PPO-Lag learns lac/PointHazard-v0 safely with the tiny preset, and the multiplier is what makes it safe.

Seed 0, 40k env steps each (20 iterations of 2000; about 30 s per run on one core). Measured here
(return / cost, the mean of the last 3 iterations; ν's peak): seed 0 ends at 0.69 / 0.90 (limit 2),
ν peaking at 0.25, and with ν pinned at 0 at 0.69 / 5.78 (the straight path through the hazard);
seed 1: 0.13 / 0.58, ν 0.59, against 0.79 / 6.91; seed 2: 0.66 / 0.28, ν 0.61, against 0.87 / 6.82.
A random policy scores −10.1. The detour around the hazard costs little return.
"""

import pytest
from conftest import assert_learns_unsafely, assert_learns_within, learning_run

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig

# One worker runs this module: its module-scoped fixtures are expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("ppo_lag_learning"), pytest.mark.slow]

TASK, STEPS, TAIL = "lac/PointHazard-v0", 40_000, 3  # judge the last TAIL iterations, not one noisy one
LIMIT = 2.0


def _run(**sets):
    return learning_run(PPOLagConfig.build(TASK, 0, sets, timesteps=STEPS), STEPS, TAIL)


@pytest.fixture(scope="module")
def lagrangian_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def pinned_run(ray_session):
    return _run(nu_init=0.0, lagrangian_lr=0.0)  # ν pinned at 0: the same PPO, no constraint


def test_ppo_lag_is_safe_and_learns(lagrangian_run, pinned_run):
    assert PPOLagConfig.build(TASK, 0, {}, timesteps=STEPS).effective_cost_limit == LIMIT
    assert_learns_within(lagrangian_run, LIMIT, nu_peak=0.1)
    cost = lagrangian_run[1]
    assert cost < pinned_run[1] - 2.0, f"cost {cost:.2f} not clearly below the pinned run's {pinned_run[1]:.2f}"


def test_the_multiplier_does_the_work(pinned_run):
    assert_learns_unsafely(pinned_run, LIMIT)
