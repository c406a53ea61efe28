"""LAC learns lac/PointHazard-v0 safely, and the constraint is what makes it safe.

Fixed seeds; ~45k env steps each (about a minute per run on 2 idle cores). Bounds were set from
runs on seeds 0 and 1: LAC ends at cost 0 (limit 2) with return ≈ 0 ± 0.7; pinned at ν = 0 it
ends at cost ≈ 11. A random policy scores ≈ −10. With the authors' dynamics as defaults (ν bound,
lr decay over the 45k budget, head init, std floor; the tiny preset has no chain clip) seed 0
ends at return −0.9, cost 0, ν peaking at 5.5.
"""

import pytest
from conftest import assert_learns_unsafely, assert_learns_within, learning_run, tiny_config

# One worker runs this module: its module-scoped fixture is expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("learning"), pytest.mark.slow]

STEPS, TAIL = 45_000, 5  # judge the last TAIL iterations, not one noisy one


def _run(**overrides):
    return learning_run(tiny_config(seed=0, total_env_steps=STEPS, **overrides), STEPS, TAIL)


@pytest.fixture(scope="module")
def lac_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def unconstrained_run(ray_session):
    return _run(nu_lr=0.0)  # ν stays at ν₀ = 0: same LAC, no constraint


def test_lac_is_safe_and_learns(lac_run):
    assert_learns_within(lac_run, tiny_config().effective_cost_limit, nu_peak=0.5)


def test_constraint_does_the_work(unconstrained_run, lac_run):
    assert_learns_unsafely(unconstrained_run, tiny_config().effective_cost_limit)
