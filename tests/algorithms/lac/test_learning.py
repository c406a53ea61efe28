"""LAC learns lac/PointHazard-v0 safely, and the constraint is what makes it safe.

Fixed seeds; ~45k env steps each (about a minute per run on 2 idle cores). Bounds were set from
runs on seeds 0 and 1: LAC ends at cost 0 (limit 2) with return ≈ 0 ± 0.7; pinned at ν = 0 it
ends at cost ≈ 11. A random policy scores ≈ −10. With the authors' dynamics as defaults (ν bound,
lr decay over the 45k budget, head init, std floor; the tiny preset has no chain clip) seed 0
ends at return −0.9, cost 0, ν peaking at 5.5.
"""

import numpy as np
import pytest
from conftest import tiny_config

from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN, NU
from lac_rllib.tasks.point_hazard import PointHazardEnv

# One worker runs this module: its module-scoped fixture is expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("learning"), pytest.mark.slow]

STEPS, TAIL = 45_000, 5  # judge the last TAIL iterations, not one noisy one


def _run(**overrides):
    algo = tiny_config(seed=0, total_env_steps=STEPS, **overrides).build_algo()
    history = []
    try:
        while not history or history[-1][ENV_STEPS] < STEPS:
            r = algo.train()
            history.append({k: float(r[k]) for k in (EPISODE_RETURN, EPISODE_COST, NU, ENV_STEPS)})
    finally:
        algo.stop()
    tail = history[-TAIL:]
    return (np.mean([h[EPISODE_RETURN] for h in tail]), np.mean([h[EPISODE_COST] for h in tail]),
            max(h[NU] for h in history))


def _random_policy_return(episodes=30, seed=0):
    env, rng, total = PointHazardEnv(), np.random.default_rng(seed), []
    for i in range(episodes):
        env.reset(seed=seed + i)
        ret, done = 0.0, False
        while not done:
            _, r, term, trunc, _ = env.step(rng.uniform(-1, 1, size=2))
            ret, done = ret + r, term or trunc
        total.append(ret)
    return float(np.mean(total))


@pytest.fixture(scope="module")
def lac_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def unconstrained_run(ray_session):
    return _run(nu_lr=0.0)  # ν stays at ν₀ = 0: same LAC, no constraint


def test_lac_is_safe_and_learns(lac_run):
    ret, cost, nu_max = lac_run
    limit = tiny_config().effective_cost_limit
    assert cost <= limit, f"final episode cost {cost:.2f} above the limit {limit}"
    random_return = _random_policy_return()
    assert ret > random_return + 5.0, f"return {ret:.2f} not clearly above random {random_return:.2f}"
    assert nu_max > 0.5, "ν never rose: the constraint was never active"


def test_constraint_does_the_work(unconstrained_run, lac_run):
    ret, cost, nu_max = unconstrained_run
    limit = tiny_config().effective_cost_limit
    assert nu_max == 0.0
    assert cost > 2 * limit, f"unconstrained cost {cost:.2f} should exceed the limit {limit}"
    assert ret > _random_policy_return() + 5.0  # it learns the task, just not safely
