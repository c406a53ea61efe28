"""SAC-Lag learns lac/PointHazard-v0 with the tiny preset, and its multiplier is what keeps it under the
limit: the same run with λ pinned at λ₀ = 0 ends above it.

Fixed seed; STEPS env steps per run (~2-2.5 min of a core each). Measured over the last TAIL
iterations: seed 0, λ: cost 1.04 (limit 2), return 0.81, λ peaking at 1.9 and swinging between 0
and ~1.4 as Ĵ_C crosses the limit; pinned at λ = 0: cost 7.2, return 0.82 (it takes the straight
path through the hazard). Seed 1: 1.14 / 0.82 against 7.15 / 0.83. A random policy scores ≈ −10.
"""

import pytest
from conftest import assert_learns_unsafely, assert_learns_within, learning_run

from lac_rllib.algorithms.sac_lag.config import SACLagConfig

# One worker runs these (with LAC's learning runs): each module-scoped run takes minutes of a core.
pytestmark = [pytest.mark.xdist_group("learning"), pytest.mark.slow]

TASK, STEPS, TAIL = "lac/PointHazard-v0", 30_000, 10  # judge the last TAIL iterations (10k steps)


def _run(**sets):
    return learning_run(SACLagConfig.build(TASK, 0, sets), STEPS, TAIL)


@pytest.fixture(scope="module")
def lagrangian_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def pinned_run(ray_session):
    return _run(lagrangian_lr=0.0)  # λ stays at the tiny preset's λ₀ = 0: SAC with a cost critic


def test_the_lagrangian_run_learns_within_the_limit(lagrangian_run):
    assert_learns_within(lagrangian_run, SACLagConfig.build(TASK, 0, {}).effective_cost_limit, nu_peak=0.5)


def test_the_multiplier_does_the_work(lagrangian_run, pinned_run):
    assert_learns_unsafely(pinned_run, SACLagConfig.build(TASK, 0, {}).effective_cost_limit)
    assert lagrangian_run[1] < pinned_run[1] / 2
