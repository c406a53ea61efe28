"""The Lagrange multiplier object: eq. (14)'s projected step, [C]'s adaptive bound, the Adam and PID
step rules, and the state a checkpoint carries (all against hand-computed values)."""

import numpy as np
import pytest
import torch

from lac_rllib.constrained.lagrange import AdamStep, AdaptiveBound, GradientStep, LagrangeMultiplier, SoftplusAdamStep


def _multiplier(nu=0.0, limit=25.0, rule=None, bounded=False, bound=None):
    value = torch.tensor(float(nu))
    return LagrangeMultiplier(value, cost_limit=limit, rule=rule or GradientStep(0.01), bound=bound,
                              bounded=bounded), value


@pytest.mark.parametrize("nu,cost,limit,lr,expected", [
    (0.0, 30.0, 25.0, 0.01, 0.05),   # over the limit: ν rises by α(Ĵ − b)
    (1.0, 20.0, 25.0, 0.01, 0.95),   # under the limit: ν falls
    (0.01, 0.0, 25.0, 0.01, 0.0),    # projection at 0
    (0.5, 25.0, 25.0, 0.01, 0.5),    # at the limit: unchanged
])
def test_projected_step_of_eq_14(nu, cost, limit, lr, expected):
    multiplier, buffer = _multiplier(nu, limit, GradientStep(lr))
    assert multiplier.step(cost) == pytest.approx(expected)
    assert float(buffer) == pytest.approx(expected)  # the module's buffer is the value


def test_no_completed_episode_no_step():
    multiplier, buffer = _multiplier(0.3)
    assert multiplier.step(None) == pytest.approx(0.3) and float(buffer) == pytest.approx(0.3)


def test_adaptive_bound_caps_the_step():
    # ν_max = 2 until the first iteration ends: 1.9 + 0.01·75 = 2.65 is held at 2.
    multiplier, _ = _multiplier(1.9, bounded=True)
    assert multiplier.upper == 2.0 and multiplier.step(100.0) == 2.0
    # Then 2·|ȳ_R| / |ȳ_C| over every minibatch of the iteration: ȳ_R = −3, ȳ_C = 12 → 0.5.
    multiplier.bound.start_iteration()
    multiplier.bound.observe(torch.tensor([-1.0, -2.0]), torch.tensor([10.0, 10.0]))
    multiplier.bound.observe(torch.tensor([-6.0, -3.0]), torch.tensor([14.0, 14.0]))
    assert multiplier.bound.end_iteration() == pytest.approx((-3.0, 12.0))
    assert multiplier.upper == pytest.approx(0.5)
    assert multiplier.step(100.0) == pytest.approx(0.5)
    # Unbounded (eq. 14 as the paper writes it): the same tracker, no cap.
    free, _ = _multiplier(1.9, bounded=False)
    assert free.upper is None and free.step(100.0) == pytest.approx(2.65)


def test_bound_without_minibatches_keeps_its_value():
    bound = AdaptiveBound()
    bound.start_iteration()
    assert bound.end_iteration() is None and bound.value == 2.0


def test_state_round_trip_gives_the_same_next_step():
    rng = np.random.default_rng(0)
    for rule in (lambda: GradientStep(0.01), lambda: AdamStep(0.035), lambda: SoftplusAdamStep(0.05, 1.0)):
        a, a_nu = _multiplier(0.001, rule=rule(), bounded=True)
        for cost in rng.uniform(0, 60, 5):
            a.bound.start_iteration()
            a.bound.observe(torch.tensor([-5.0]), torch.tensor([float(cost)]))
            a.step(cost)
            a.bound.end_iteration()
        b, b_nu = _multiplier(0.0, rule=rule(), bounded=True)
        b.set_state(a.get_state())
        b_nu.copy_(a_nu)  # ν itself travels in the module's weights
        assert b.upper == a.upper and b.get_state() == a.get_state()
        assert b.step(40.0) == a.step(40.0)


def test_adam_step_equals_torch_adam_plus_clamp():
    """OmniSafe's Lagrange: torch.optim.Adam on −λ·(J_c − d), then λ clamped at 0."""
    rng = np.random.default_rng(1)
    costs = rng.uniform(0.0, 60.0, 50)
    lam = torch.nn.Parameter(torch.tensor(0.001, dtype=torch.float64))
    optim = torch.optim.Adam([lam], lr=0.035)
    ours, _ = _multiplier(0.001, limit=25.0, rule=AdamStep(0.035))
    ours._value = torch.tensor(0.001, dtype=torch.float64)  # compare in float64
    for cost in costs:
        optim.zero_grad()
        (-lam * (float(cost) - 25.0)).backward()
        optim.step()
        with torch.no_grad():
            lam.clamp_(min=0.0)
        assert ours.step(float(cost)) == pytest.approx(float(lam.detach()), abs=1e-7)
