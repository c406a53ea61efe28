"""SAC-Lag learns lac/PointHazard-v0 with the tiny preset, and its multiplier is what keeps it under the
limit: the same run with λ pinned at λ₀ = 0 ends above it.

Fixed seed; STEPS env steps per run (~2-2.5 min of a core each). Measured over the last TAIL
iterations: seed 0, λ: cost 1.04 (limit 2), return 0.81, λ peaking at 1.9 and swinging between 0
and ~1.4 as Ĵ_C crosses the limit; pinned at λ = 0: cost 7.2, return 0.82 (it takes the straight
path through the hazard). Seed 1: 1.14 / 0.82 against 7.15 / 0.83. A random policy scores ≈ −10.
"""

import numpy as np
import pytest

from lac_rllib.algorithms.sac_lag.config import build_config
from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN, NU
from lac_rllib.tasks.point_hazard import PointHazardEnv

# One worker runs these (with LAC's learning runs): each module-scoped run takes minutes of a core.
pytestmark = [pytest.mark.xdist_group("learning"), pytest.mark.slow]

TASK, STEPS, TAIL = "lac/PointHazard-v0", 30_000, 10  # judge the last TAIL iterations (10k steps)


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


def _run(**sets):
    algo = build_config(TASK, 0, sets).build_algo()
    history = []
    try:
        while not history or history[-1][ENV_STEPS] < STEPS:
            r = algo.train()
            history.append({k: float(r[k]) for k in (EPISODE_RETURN, EPISODE_COST, NU, ENV_STEPS)})
    finally:
        algo.stop()
    tail = history[-TAIL:]
    return (float(np.mean([h[EPISODE_RETURN] for h in tail])), float(np.mean([h[EPISODE_COST] for h in tail])),
            max(h[NU] for h in history))


@pytest.fixture(scope="module")
def lagrangian_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def pinned_run(ray_session):
    return _run(lagrangian_lr=0.0)  # λ stays at the tiny preset's λ₀ = 0: SAC with a cost critic


def test_the_lagrangian_run_learns_within_the_limit(lagrangian_run):
    ret, cost, nu_max = lagrangian_run
    limit = build_config(TASK, 0, {}).effective_cost_limit
    assert cost <= limit, f"tail episode cost {cost:.2f} above the limit {limit}"
    random_return = _random_policy_return()
    assert ret > random_return + 5.0, f"tail return {ret:.2f} not clearly above random {random_return:.2f}"
    assert nu_max > 0.5, "λ never rose: the constraint never acted"


def test_the_multiplier_does_the_work(lagrangian_run, pinned_run):
    ret, cost, nu_max = pinned_run
    limit = build_config(TASK, 0, {}).effective_cost_limit
    assert nu_max == 0.0
    assert cost > 2 * limit, f"pinned at λ = 0 the tail cost {cost:.2f} should be well above the limit {limit}"
    assert ret > _random_policy_return() + 5.0  # it learns the task, just not safely
    assert lagrangian_run[1] < cost / 2
