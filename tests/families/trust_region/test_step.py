"""The shared trust-region step (lac_rllib/families/trust_region/step.py): CG on an SPD system, the
Fisher-vector product against an explicit Hessian of the mean KL (and blind to phantom rows), the
line search's accept/reject and bit-for-bit restore, CPO's dual against a brute-force 2-D quadratic
programme in each case (an exact enumeration of the feasible set's boundary), and PCPO's
projections against the analytic ones and scipy's SLSQP. Pure torch, float64, seconds in total."""

import functools
import math

import numpy as np
import pytest
import torch
from scipy.optimize import minimize
from torch.func import functional_call

from lac_rllib.families.trust_region.step import (
    conjugate_gradient,
    cpo_acceptance,
    cpo_step,
    fisher_vector_product,
    flat_grad,
    flat_params,
    line_search,
    masked_mean,
    pcpo_step,
    set_flat_params_,
    trpo_acceptance,
    trpo_step,
)

DELTA = 0.01
_t = functools.partial(torch.tensor, dtype=torch.float64)


# --- flat parameters and CG ------------------------------------------------------------------------

def test_flat_params_round_trip_and_flat_grad_fills_unused_parameters():
    net, unused = torch.nn.Linear(3, 2), torch.nn.Parameter(torch.ones(4))
    params = [*net.parameters(), unused]
    theta = flat_params(params)
    assert theta.shape == (3 * 2 + 2 + 4,)
    set_flat_params_(params, theta + 1.0)
    set_flat_params_(params, theta)
    assert torch.equal(flat_params(params), theta)
    assert flat_params(params).data_ptr() != theta.data_ptr() and net.weight.data_ptr() != theta.data_ptr()
    grad = flat_grad(net(torch.ones(1, 3)).sum(), params)
    assert torch.equal(grad[-4:], torch.zeros(4)) and torch.equal(grad[:6], torch.ones(6))
    with pytest.raises(ValueError):
        set_flat_params_(params, theta[:-1])


def test_cg_solves_a_random_spd_system_in_at_most_20_products():
    gen = torch.Generator().manual_seed(0)
    m = torch.randn(20, 20, generator=gen, dtype=torch.float64)
    A = m @ m.T / 20 + torch.eye(20, dtype=torch.float64)  # eigenvalues in about [1, 5], as a damped Fisher
    b = torch.randn(20, generator=gen, dtype=torch.float64)
    calls = []

    def Avp(v):
        calls.append(1)
        return A @ v

    x = conjugate_gradient(Avp, b, iters=20)
    assert len(calls) <= 20
    assert torch.linalg.norm(A @ x - b) < 1e-6
    assert torch.allclose(x, torch.linalg.solve(A, b), atol=1e-6)
    calls.clear()
    assert torch.equal(conjugate_gradient(Avp, torch.zeros(20)), torch.zeros(20)) and not calls  # b = 0: no NaN


# --- a tiny Gaussian policy: tanh MLP mean, free log σ ------------------------------------------------

class Policy(torch.nn.Module):
    def __init__(self):
        super().__init__()
        torch.manual_seed(0)
        self.mean = torch.nn.Sequential(torch.nn.Linear(3, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))
        self.log_std = torch.nn.Parameter(torch.tensor([-0.3, 0.2]))
        self.double()

    def forward(self, obs):
        return self.mean(obs), self.log_std.expand(obs.shape[0], 2)


def _kl_rows(old, new):
    """KL(N(μ₀, σ₀) ‖ N(μ, σ)) per row, summed over action dimensions (RLlib's convention)."""
    (mu0, log_std0), (mu, log_std) = old, new
    var0, var = (2 * log_std0).exp(), (2 * log_std).exp()
    return (log_std - log_std0 + (var0 + (mu0 - mu) ** 2) / (2 * var) - 0.5).sum(-1)


def _loss_rows(policy_out, act, logp_old, adv):
    """The importance-weighted surrogate's loss per row, −ratio·A [O policy_gradient.py:578]."""
    mu, log_std = policy_out
    logp = torch.distributions.Normal(mu, log_std.exp()).log_prob(act).sum(-1)
    return -(logp - logp_old).exp() * adv


def _batch(n, seed):
    gen = torch.Generator().manual_seed(seed)
    obs, act, adv = (torch.randn(n, d, generator=gen, dtype=torch.float64) for d in (3, 2, 1))
    return obs, act, adv.squeeze(-1)


def _problem(policy, obs, act, adv, mask=None):
    """The masked surrogate loss and mean-KL closures of a TRPO step at the current parameters."""
    with torch.no_grad():
        old = policy(obs)
        logp_old = torch.distributions.Normal(old[0], old[1].exp()).log_prob(act).sum(-1)

    def loss_fn():
        return masked_mean(_loss_rows(policy(obs), act, logp_old, adv), mask)

    def kl_fn():
        return masked_mean(_kl_rows(old, policy(obs)), mask)

    return loss_fn, kl_fn


def test_fvp_equals_the_explicit_hessian_of_the_mean_kl():
    policy = Policy()
    obs, act, adv = _batch(8, seed=1)
    _, kl_fn = _problem(policy, obs, act, adv)
    names = [n for n, _ in policy.named_parameters()]
    params = list(policy.parameters())
    theta0 = flat_params(params)
    with torch.no_grad():
        old = policy(obs)

    def mean_kl(theta):
        chunks = torch.split(theta, [p.numel() for p in params])
        weights = {n: c.view_as(p) for n, c, p in zip(names, chunks, params)}
        return _kl_rows(old, functional_call(policy, weights, (obs,))).mean()

    hessian = torch.autograd.functional.hessian(mean_kl, theta0)
    v = torch.randn(theta0.numel(), generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    for damping in (0.0, 0.1):
        fvp = fisher_vector_product(kl_fn, params, damping)
        assert torch.allclose(fvp(v), hessian @ v + damping * v, atol=1e-5, rtol=0)
        assert torch.allclose(fvp(2 * v), 2 * (hessian @ v + damping * v), atol=1e-5, rtol=0)  # reusable
    assert torch.linalg.norm(hessian @ v) > 1e-2  # the comparison is not 0 = 0


def test_phantom_rows_change_neither_the_product_nor_the_surrogate():
    policy = Policy()
    params = list(policy.parameters())
    obs, act, adv = _batch(8, seed=3)
    junk_obs, junk_act, junk_adv = (50 * t for t in _batch(4, seed=4))
    padded = [torch.cat(pair) for pair in ((obs, junk_obs), (act, junk_act), (adv, junk_adv))]
    mask = torch.cat([torch.ones(8, dtype=torch.bool), torch.zeros(4, dtype=torch.bool)])
    v = torch.randn(flat_params(params).numel(), generator=torch.Generator().manual_seed(5), dtype=torch.float64)

    real_loss, real_kl = _problem(policy, obs, act, adv)
    pad_loss, pad_kl = _problem(policy, *padded, mask=mask)
    assert torch.allclose(pad_loss(), real_loss(), atol=1e-12, rtol=0)
    assert torch.allclose(flat_grad(pad_loss(), params), flat_grad(real_loss(), params), atol=1e-12, rtol=0)
    fvp_real, fvp_pad = (fisher_vector_product(kl, params, 0.1) for kl in (real_kl, pad_kl))
    assert torch.allclose(fvp_pad(v), fvp_real(v), atol=1e-12, rtol=0)
    # Unmasked, the phantom rows would show in both.
    open_loss, open_kl = _problem(policy, *padded)
    assert not torch.allclose(open_loss(), real_loss(), atol=1e-6)
    assert not torch.allclose(fisher_vector_product(open_kl, params, 0.1)(v), fvp_real(v), atol=1e-6)


# --- the line search -------------------------------------------------------------------------------

def _natural_step(policy, loss_fn, kl_fn):
    params = list(policy.parameters())
    g = -flat_grad(loss_fn(), params)
    x = conjugate_gradient(fisher_vector_product(kl_fn, params, 0.1), g, iters=20)
    return trpo_step(x, g @ x, DELTA)


def test_line_search_rejects_an_over_kl_step_and_restores_theta_old_bit_for_bit():
    policy = Policy()
    params = list(policy.parameters())
    loss_fn, kl_fn = _problem(policy, *_batch(16, seed=6))
    step = 50 * _natural_step(policy, loss_fn, kl_fn)
    before = [p.detach().clone() for p in params]
    theta_old, seen = flat_params(params), []
    trpo_test = trpo_acceptance(loss_fn, kl_fn, loss_fn().item(), DELTA)

    def accept(fraction):
        seen.append((fraction, float(kl_fn())))
        assert torch.equal(flat_params(params), theta_old + fraction * step)  # evaluated AT the trial point
        return trpo_test(fraction)

    result = line_search(params, step, accept, backtracks=3, decay=0.8)
    assert (result.accepted, result.fraction, result.backtracks) == (False, 0.0, 3)
    assert [f for f, _ in seen] == pytest.approx([1.0, 0.8, 0.64]) and min(kl for _, kl in seen) > DELTA
    assert all(torch.equal(p, q) for p, q in zip(params, before))


def test_line_search_accepts_a_trust_region_step_within_the_kl_bound_that_improves_the_surrogate():
    policy = Policy()
    params = list(policy.parameters())
    loss_fn, kl_fn = _problem(policy, *_batch(16, seed=7))
    step, theta_old, loss_old = _natural_step(policy, loss_fn, kl_fn), flat_params(params), loss_fn().item()
    result = line_search(params, step, trpo_acceptance(loss_fn, kl_fn, loss_old, DELTA), backtracks=10)
    assert result.accepted and result.fraction == 0.8**result.backtracks
    assert torch.equal(flat_params(params), theta_old + result.fraction * step)  # left at the accepted point
    with torch.no_grad():
        assert 0 < float(kl_fn()) <= DELTA and float(loss_fn()) < loss_old


def test_acceptance_tests_reject_non_finite_values_and_broken_distributions():
    one, nan = (lambda: torch.tensor(0.0)), (lambda: torch.tensor(math.nan))

    def broken():
        raise ValueError("Expected parameter loc to satisfy the constraint Real()")

    assert trpo_acceptance(one, one, 0.0, DELTA)(1.0)
    assert not trpo_acceptance(nan, one, 0.0, DELTA)(1.0) and not trpo_acceptance(one, nan, 0.0, DELTA)(1.0)
    assert not trpo_acceptance(broken, one, 0.0, DELTA)(1.0)
    assert not cpo_acceptance(one, nan, one, 0.0, 0.0, -1.0, DELTA, case=2)(1.0)


@pytest.mark.parametrize("loss,cost,kl,c,case,expected", [
    (0.1, 0.0, 0.005, -1.0, 2, False),   # loss rose: rejected in cases 2-4 ...
    (0.1, 0.0, 0.005, 1.0, 1, True),     # ... but not in recovery (cases 0-1)
    (-0.1, 0.5, 0.005, -1.0, 3, True),   # cost may rise by up to −c when feasible
    (-0.1, 1.5, 0.005, -1.0, 3, False),
    (-0.1, 0.01, 0.005, 1.0, 0, False),  # infeasible: the cost may not rise at all
    (-0.1, -0.2, 0.005, 1.0, 0, True),
    (-0.1, 0.0, 0.02, -1.0, 2, False),   # KL above δ
])
def test_cpo_acceptance_rules(loss, cost, kl, c, case, expected):
    accept = cpo_acceptance(lambda: torch.tensor(loss), lambda: torch.tensor(cost), lambda: torch.tensor(kl),
                            loss_old=0.0, cost_old=0.0, c=c, max_kl=DELTA, case=case)
    assert accept(1.0) is expected


# --- CPO's dual against a brute-force QP in 2-D ------------------------------------------------------

H = np.array([[2.0, 0.6], [0.6, 1.0]])
G = np.array([1.0, 0.5])
RADIUS = 0.5  # δ of the 2-D problems: ½xᵀHx ≤ 0.5


def _cpo(b, c, convention="paper"):
    hinv = np.linalg.inv(H)
    return cpo_step(_t(G), _t(b), _t(hinv @ G), _t(hinv @ b), c, RADIUS, convention=convention)


def _slsqp(objective, constraints):
    cons = [{"type": "ineq", "fun": f} for f in constraints]
    res = minimize(objective, np.zeros(2), constraints=cons, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
    assert res.success, res.message
    return res.x


def _boundary(n=2_000_001):
    """Points of the trust region's boundary ½xᵀHx = δ, a dense grid in angle."""
    angle = np.linspace(0, 2 * np.pi, n)
    return math.sqrt(2 * RADIUS) * np.linalg.solve(np.linalg.cholesky(H).T, [np.cos(angle), np.sin(angle)])


def _brute_force(b, c):
    """max gᵀx s.t. ½xᵀHx ≤ δ, bᵀx + c ≤ 0 [CPO §6.1]; with no feasible point, min bᵀx on the
    trust region (what recovery aims at). A linear objective on an ellipse cut by a half-plane is
    maximised on the boundary of the feasible set: on the ellipse's feasible arc (a dense grid) or
    at an end of the chord, where the line bᵀx + c = 0 meets the ellipse (solved exactly). No
    optimiser: SLSQP started from an infeasible θ_old fails on some scipy releases."""
    boundary = _boundary()
    if c ** 2 / (b @ np.linalg.solve(H, b)) > 2 * RADIUS and c >= 0:  # no feasible point
        return boundary[:, np.argmin(b @ boundary)]
    # the chord's ends in the unit-circle coordinates u of x = √(2δ)·L⁻ᵀu, where the line is wᵀu = −c
    L = np.linalg.cholesky(H)
    w = math.sqrt(2 * RADIUS) * np.linalg.solve(L, b)
    ww = w @ w
    ends = []
    if c ** 2 <= ww:
        across = np.array([-w[1], w[0]]) * math.sqrt(ww - c ** 2) / ww
        ends = [math.sqrt(2 * RADIUS) * np.linalg.solve(L.T, -c * w / ww + sign * across) for sign in (1, -1)]
    candidates = np.column_stack([boundary[:, b @ boundary + c <= 0], *ends])
    return candidates[:, np.argmax(G @ candidates)]


@pytest.mark.parametrize("b,c,case,active", [
    ([1.0, 0.0], -5.0, 3, False),   # the whole trust region is feasible: the TRPO step
    ([-1.0, 1.0], -0.3, 2, False),  # the boundary cuts the trust region, the TRPO step misses it
    ([1.0, 0.2], -0.2, 2, True),    # ... and it is active
    ([0.8, 0.6], 0.2, 1, True),     # θ_old infeasible, feasible recovery
    ([-0.5, 1.0], 0.3, 1, True),
    ([0.8, 0.6], 3.0, 0, True),     # no feasible point: infeasible recovery, −√(2δ/s)·H⁻¹b
])
def test_cpo_step_solves_the_2d_quadratic_programme(b, c, case, active):
    b = np.array(b)
    result = _cpo(b, c)
    x = result.step_direction.numpy()
    assert result.case == case
    assert np.allclose(x, _brute_force(b, c), atol=1e-5)
    assert 0.5 * x @ H @ x == pytest.approx(RADIUS, abs=1e-6)  # a linear objective ends on the trust region
    if case > 0:
        assert (result.nu > 1e-6) == active and (b @ x + c == pytest.approx(0.0, abs=1e-6)) == active


def test_cpo_step_without_a_cost_gradient_is_the_trpo_step():
    result = _cpo(np.zeros(2), -1.0)
    x_trpo = math.sqrt(2 * RADIUS / (G @ np.linalg.solve(H, G))) * np.linalg.solve(H, G)
    assert result.case == 4 and result.nu == 0.0 and np.allclose(result.step_direction.numpy(), x_trpo)


@pytest.mark.parametrize("b,c", [([1.0, 0.2], -0.2), ([0.8, 0.6], 0.2), ([-0.5, 1.0], 0.3)])
def test_omnisafe_convention_reproduces_its_sign_of_r_and_misses_the_optimum(b, c):
    b = np.array(b)
    paper, omnisafe = _cpo(b, c), _cpo(b, c, convention="omnisafe")
    assert (paper.case, paper.A, paper.B) == (omnisafe.case, omnisafe.A, omnisafe.B)
    assert not np.allclose(omnisafe.step_direction.numpy(), _brute_force(b, c), atol=1e-2)


# --- PCPO's projection -------------------------------------------------------------------------------

def _pcpo(h, b, c, metric):
    hinv = np.linalg.inv(h)
    return pcpo_step(_t(G), _t(b), _t(hinv @ G), _t(hinv @ b), c, RADIUS, metric=metric)


def test_pcpo_projections_match_the_analytic_ones():
    b, c = np.array([1.0, 0.2]), -0.2
    half = math.sqrt(2 * RADIUS / (G @ np.linalg.solve(H, G))) * np.linalg.solve(H, G)  # [PCPO] reward step
    assert b @ half + c > 0.1  # it violates the constraint, so the projections act
    for metric, L in (("kl", H), ("l2", np.eye(2))):
        x = _pcpo(H, b, c, metric).step_direction.numpy()
        analytic = half - (b @ half + c) / (b @ np.linalg.solve(L, b)) * np.linalg.solve(L, b)
        nearest = _slsqp(lambda y: 0.5 * (y - half) @ L @ (y - half), [lambda y: -(b @ y + c)])
        assert np.allclose(x, analytic, atol=1e-10) and np.allclose(x, nearest, atol=1e-5)
        assert b @ x + c == pytest.approx(0.0, abs=1e-7)
    # OmniSafe: the reward step along η·g, the KL projection's coefficient: off the boundary as H ≠ I.
    eta = math.sqrt(2 * RADIUS / (G @ np.linalg.solve(H, G)))
    nu = (b @ half + c) / (b @ np.linalg.solve(H, b))
    x = _pcpo(H, b, c, "omnisafe")
    assert x.nu == pytest.approx(nu) and np.allclose(x.step_direction.numpy(), eta * G - nu * np.linalg.solve(H, b))
    assert abs(b @ x.step_direction.numpy() + c) > 1e-2
    # With H = I the three agree.
    steps = [_pcpo(np.eye(2), b, c, m).step_direction.numpy() for m in ("kl", "l2", "omnisafe")]
    assert np.allclose(steps[0], steps[1]) and np.allclose(steps[0], steps[2])


def test_pcpo_leaves_a_feasible_reward_step_alone():
    b, c = np.array([-1.0, 1.0]), -0.3
    half = math.sqrt(2 * RADIUS / (G @ np.linalg.solve(H, G))) * np.linalg.solve(H, G)
    for metric in ("kl", "l2"):
        result = _pcpo(H, b, c, metric)
        assert result.nu == 0.0 and np.allclose(result.step_direction.numpy(), half)
    with pytest.raises(ValueError):
        _pcpo(H, b, c, "fisher")
