"""PPO-Lag learns lac/PointHazard-v0 safely with the tiny preset, and the multiplier is what makes it safe.

Seed 0, 40k env steps each (20 iterations of 2000; about 30 s per run on one core). Measured here
(return / cost, the mean of the last 3 iterations; ν's peak): seed 0 ends at 0.69 / 0.90 (limit 2),
ν peaking at 0.25, and with ν pinned at 0 at 0.69 / 5.78 (the straight path through the hazard);
seed 1: 0.13 / 0.58, ν 0.59, against 0.79 / 6.91; seed 2: 0.66 / 0.28, ν 0.61, against 0.87 / 6.82.
A random policy scores −10.1. The detour around the hazard costs little return.
"""

import numpy as np
import pytest

from lac_rllib.algorithms.ppo_lag.config import build_config
from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN, NU
from lac_rllib.tasks.point_hazard import PointHazardEnv

# One worker runs this module: its module-scoped fixtures are expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("ppo_lag_learning"), pytest.mark.slow]

TASK, STEPS, TAIL = "lac/PointHazard-v0", 40_000, 3  # judge the last TAIL iterations, not one noisy one
LIMIT = 2.0


def _run(**sets):
    algo = build_config(TASK, 0, sets, timesteps=STEPS).build_algo()
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
def lagrangian_run(ray_session):
    return _run()


@pytest.fixture(scope="module")
def pinned_run(ray_session):
    return _run(nu_init=0.0, lagrangian_lr=0.0)  # ν pinned at 0: the same PPO, no constraint


def test_ppo_lag_is_safe_and_learns(lagrangian_run, pinned_run):
    ret, cost, nu_max = lagrangian_run
    assert build_config(TASK, 0, {}, timesteps=STEPS).effective_cost_limit == LIMIT
    assert cost <= LIMIT, f"final episode cost {cost:.2f} above the limit {LIMIT}"
    assert cost < pinned_run[1] - 2.0, f"cost {cost:.2f} not clearly below the pinned run's {pinned_run[1]:.2f}"
    random_return = _random_policy_return()
    assert ret > random_return + 5.0, f"return {ret:.2f} not clearly above random {random_return:.2f}"
    assert nu_max > 0.1, f"ν peaked at {nu_max:.3f}: the constraint was never active"


def test_the_multiplier_does_the_work(pinned_run):
    ret, cost, nu_max = pinned_run
    assert nu_max == 0.0
    assert cost > 2 * LIMIT, f"unconstrained cost {cost:.2f} should exceed the limit {LIMIT}"
    assert ret > _random_policy_return() + 5.0  # it learns the task, just not safely
