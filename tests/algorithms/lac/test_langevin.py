"""Langevin chain (Algorithm 1, eq. 9/11): Theorem 3.1 on quadratics, equality of the efficient
form with the naive autograd reference, and the chain's contracts (no parameter gradients,
detached output, bounds, start distribution, the gradient clip's two modes, chain-health figures,
argument validation)."""

import math

import pytest
import torch
from conftest import chain

from lac_rllib.algorithms.lac.langevin import INFORMATIVE, STARTS, naive_langevin_chain, run_chain
from lac_rllib.constrained.networks import CriticEnsemble, GaussianActor

D64 = torch.float64
M_STRONG, L_SMOOTH = 1.0, 4.0  # m I ⪯ ∇²E ⪯ l I


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _quadratic(d: int, seed: int):
    """E(a) = ½(a−m)ᵀA(a−m), spectrum of A spread over [m, l] in a random basis."""
    g = torch.Generator().manual_seed(seed)
    rot, _ = torch.linalg.qr(torch.randn(d, d, generator=g, dtype=D64))
    A = rot @ torch.diag(torch.linspace(M_STRONG, L_SMOOTH, d, dtype=D64)) @ rot.T
    centre = torch.randn(d, generator=g, dtype=D64)

    def grad_fn(a):
        diff = a - centre
        return 0.5 * ((diff @ A) * diff).sum(-1), diff @ A

    return A, centre, grad_fn


def _gauss_kl(mu0, cov0, mu1, cov1):
    """KL(N0 ‖ N1) in closed form."""
    d = mu0.numel()
    prec1 = torch.linalg.inv(cov1)
    diff = mu1 - mu0
    return 0.5 * (torch.trace(prec1 @ cov0) + diff @ prec1 @ diff - d
                  + torch.logdet(cov1) - torch.logdet(cov0))


def _sample_quadratic_chain(d, eta, steps, n=4000, seed=0):
    A, centre, grad_fn = _quadratic(d, seed)
    g = torch.Generator().manual_seed(seed + 100)
    a0 = torch.randn(n, d, generator=g, dtype=D64) / math.sqrt(M_STRONG)  # π₀ = N(0, 1/m)
    x = run_chain(grad_fn, a0, steps=steps, step_size=eta, generator=g).action
    return A, centre, x.mean(0), torch.cov(x.T)


@pytest.mark.parametrize("d", [2, 8])
def test_theorem_3_1_small_step_matches_target(d):
    """Theorem 3.1's sufficient η = mε/(8dl²) is tiny; for a quadratic the ULA bias is known
    exactly (variance × 1/(1 − ηλ_i/4), ≤ 1% here), so a moderate η already shows the limit."""
    n, eta, steps = 4000, 1e-2, 1500  # slowest mode: (1 − ηm/2)^T ≈ e^{-7.5}, mean bias < 2e-3
    A, centre, mu, cov = _sample_quadratic_chain(d, eta, steps, n)
    target_cov = torch.linalg.inv(A)
    # Whitened by the target, the sample mean is N(0, I/n) and the sample covariance is I with
    # entry s.d. ≤ √(2/n) ≈ 0.022; 5 s.d. plus the O(η·l/4) = 1% discretisation bias.
    w = torch.linalg.cholesky(A)  # A = W Wᵀ, so Wᵀ(x − m) ~ N(0, I) under the target
    z_mean = w.T @ (mu - centre)
    assert z_mean.abs().max() < 5 / math.sqrt(n)
    z_cov = w.T @ cov @ w
    assert (z_cov - torch.eye(d, dtype=D64)).abs().max() < 5 * math.sqrt(2 / n) + 0.01
    # Finite-sample KL of a fitted Gaussian ≈ (d(d+1)/2 + d)/(2n) ≤ 0.006 at d = 8.
    assert _gauss_kl(mu, cov, centre, target_cov) < 0.02


@pytest.mark.parametrize("d", [2, 8])
def test_theorem_3_1_large_step_is_measurably_biased(d):
    """η = 2/l: the chain still converges, but to N(m, A⁻¹(I − ηA/4)⁻¹), not N(m, A⁻¹)."""
    n, eta, steps = 4000, 2 / L_SMOOTH, 200
    A, centre, mu, cov = _sample_quadratic_chain(d, eta, steps, n)
    eye = torch.eye(d, dtype=D64)
    ula_cov = torch.linalg.inv(A) @ torch.linalg.inv(eye - eta * A / 4)
    kl_target = _gauss_kl(mu, cov, centre, torch.linalg.inv(A))
    kl_ula = _gauss_kl(mu, cov, centre, ula_cov)
    # Top eigen-direction variance is doubled: KL ≥ ½(2 − 1 − ln 2) ≈ 0.15 from it alone.
    assert kl_target > 0.1
    assert kl_ula < 0.02  # ...and the bias is exactly the one ULA theory predicts.


# --- LAC energy: efficient form vs naive autograd reference --------------------------------
OBS, ACT, B = 6, 3, 16


def _nets(seed=0):
    torch.manual_seed(seed)
    critics = CriticEnsemble(OBS, ACT, (16, 16, 16)).to(D64)
    actor = GaussianActor(OBS, ACT, (16, 16), log_std_init=-0.7).to(D64)
    obs = torch.randn(B, OBS, dtype=D64)
    return critics, actor, obs


@pytest.mark.parametrize("temperature", [1e-3, 0.1, 2.0])
@pytest.mark.parametrize("bounded", [False, True])
@pytest.mark.parametrize("start", STARTS)
@pytest.mark.parametrize("clip", [None, ("batch", 50.0), ("per_sample", 50.0)])
def test_efficient_chain_equals_naive(temperature, bounded, start, clip):
    critics, actor, obs = _nets()
    steps, eta = 12, 1e-3
    noise = torch.randn(steps + 1, B, ACT, generator=torch.Generator().manual_seed(5), dtype=D64)
    bounds = dict(low=-torch.ones(ACT, dtype=D64), high=torch.ones(ACT, dtype=D64)) if bounded \
        else dict(low=None, high=None)
    nu = torch.tensor(0.7, dtype=D64) if bounded else 0.7
    mean, log_std = actor(obs)
    clip_kw = dict(grad_clip=clip[1], grad_clip_mode=clip[0]) if clip else {}
    fast = chain(critics, obs, mean, log_std, steps=steps, step_size=eta,
                          temperature=temperature, nu=nu, start=start, noise=noise, **bounds, **clip_kw)
    a0 = mean.detach() + log_std.detach().exp() * noise[0] if start == INFORMATIVE else noise[0]
    slow = naive_langevin_chain(critics, actor, obs, a0, steps=steps, step_size=eta,
                                temperature=temperature, nu=nu, logp_weight=1.0,
                                noise=noise[1:], **bounds, **clip_kw)
    for field in ("action", "energy_start", "energy_end", "displacement", "grad_norm", "clip_fraction",
                  "at_bound"):
        torch.testing.assert_close(getattr(fast, field), getattr(slow, field), rtol=1e-5, atol=1e-5)
    if clip and temperature == 1e-3:
        assert float(fast.clip_fraction) > 0  # at λ = 1e-3 the clip binds: it was exercised
    assert fast.displacement.min() > 0  # the chain actually moved
    if bounded:
        assert fast.action.abs().max() <= 1.0
    assert all(p.grad is None for p in [*critics.parameters(), *actor.parameters()])


def test_chain_builds_no_parameter_gradients_and_detaches():
    critics, actor, obs = _nets()
    mean, log_std = actor(obs)  # carries a graph into the actor's parameters
    res = chain(critics, obs, mean, log_std, steps=5, step_size=1e-2,
                         temperature=0.1, nu=1.0, generator=torch.Generator().manual_seed(0))
    assert not res.action.requires_grad and res.action.grad_fn is None
    assert all(p.grad is None for p in [*critics.parameters(), *actor.parameters()])
    assert res.action.shape == (B, ACT) and res.energy_end.shape == (B,)


def test_clamps_to_bounds_after_every_step():
    critics, actor, obs = _nets()
    mean, log_std = actor(obs)
    low, high = torch.tensor([-0.1, -0.2, 0.0], dtype=D64), 0.05
    res = chain(critics, obs, mean, log_std, steps=4, step_size=0.5, temperature=1.0,
                         nu=0.0, low=low, high=high, generator=torch.Generator().manual_seed(0))
    a = res.action
    assert (a >= low).all() and (a <= high).all()
    assert (a == high).any() and (a == low).any()  # big steps do hit both walls


@pytest.mark.parametrize("start", STARTS)
def test_start_distribution(start):
    """With a negligible step, ã_T ≈ ã₀: informative ~ N(μ, σ²), non-informative ~ N(0, I)."""
    critics, _, _ = _nets()
    n = 20000
    obs = torch.zeros(n, OBS, dtype=D64)
    mean = torch.full((n, ACT), 2.0, dtype=D64)
    log_std = torch.full((n, ACT), math.log(0.3), dtype=D64)
    res = chain(critics, obs, mean, log_std, steps=1, step_size=1e-12, temperature=1e6,
                         nu=0.0, logp_weight=0.0, start=start,
                         generator=torch.Generator().manual_seed(0))
    exp_mean, exp_std = (2.0, 0.3) if start == INFORMATIVE else (0.0, 1.0)
    tol = 5 * exp_std / math.sqrt(n)
    assert (res.action.mean(0) - exp_mean).abs().max() < tol
    assert (res.action.std(0) - exp_std).abs().max() < 0.03 * exp_std


def _one_step(grad0, **kw):
    """One chain step from 0 with zero noise and gradient ``grad0``: ã₁ = −(η/2)·clip(∇)."""
    noise = torch.zeros(1, *grad0.shape, dtype=D64)
    return run_chain(lambda a: (a.sum(-1), grad0), torch.zeros_like(grad0), steps=1, step_size=2.0,
                     noise=noise, **kw)


def test_batch_clip_is_one_norm_over_the_minibatch():
    g = torch.tensor([[3.0, 4.0], [0.0, 12.0], [0.0, 0.0], [-84.0, 0.0]], dtype=D64)  # ‖g‖_F = 85
    res = _one_step(g, grad_clip=17.0, grad_clip_mode="batch")
    torch.testing.assert_close(res.action, -g * (17.0 / 85.0))  # every row shrunk by one factor
    assert float(res.clip_fraction) == 1.0
    assert float(res.grad_norm) == pytest.approx((5 + 12 + 0 + 84) / 4)  # mean per-sample, pre-clip
    below = _one_step(g, grad_clip=85.5, grad_clip_mode="batch")
    torch.testing.assert_close(below.action, -g)
    assert float(below.clip_fraction) == 0.0


def test_per_sample_clip_differs_where_samples_differ():
    g = torch.tensor([[3.0, 4.0], [0.0, 12.0], [0.0, 0.0], [-84.0, 0.0]], dtype=D64)
    res = _one_step(g, grad_clip=20.0, grad_clip_mode="per_sample")  # each row to 20/√4 = 10
    torch.testing.assert_close(res.action[0], -g[0])                  # ‖5‖ < 10: untouched
    torch.testing.assert_close(res.action[1], torch.tensor([0.0, -10.0], dtype=D64))
    torch.testing.assert_close(res.action[3], torch.tensor([10.0, 0.0], dtype=D64))
    assert float(res.clip_fraction) == pytest.approx(0.5)
    batch = _one_step(g, grad_clip=20.0, grad_clip_mode="batch")
    assert not torch.allclose(batch.action[0], res.action[0])  # the batch mode shrank row 0 too
    # Alike rows: both modes give the same step (the per-sample bound is clip/√B).
    same = g[1:2].expand(4, 2).clone()
    torch.testing.assert_close(_one_step(same, grad_clip=20.0, grad_clip_mode="per_sample").action,
                               _one_step(same, grad_clip=20.0, grad_clip_mode="batch").action)


def test_at_bound_fraction():
    g = torch.tensor([[-5.0, 0.0], [0.0, 0.1], [0.0, 0.0], [0.0, 3.0]], dtype=D64)
    res = _one_step(g, low=-1.0, high=1.0)  # rows 0 (→ +5, clamped) and 3 (→ −3, clamped)
    assert float(res.at_bound) == pytest.approx(0.5)


def test_energy_decreases_from_informative_start():
    """At the paper's λ = 1e-3 the Q terms dominate: the chain must move downhill (from π_φ'
    alone, ã₀ would already be stationary for the −log π part and show no decrease)."""
    critics, actor, _ = _nets(seed=1)
    obs = torch.randn(512, OBS, generator=torch.Generator().manual_seed(1), dtype=D64)
    mean, log_std = actor(obs)
    res = chain(critics, obs, mean, log_std, steps=30, step_size=1e-3, temperature=1e-3,
                         nu=0.5, generator=torch.Generator().manual_seed(0))
    drop = res.energy_end - res.energy_start
    assert drop.mean() < -5 * drop.std() / math.sqrt(drop.numel())  # significant, not noise
    assert (drop < 0).float().mean() > 0.6


@pytest.mark.parametrize("bad, field", [
    (dict(steps=0), "steps"), (dict(step_size=0.0), "step_size"),
    (dict(temperature=-1.0), "temperature"), (dict(start="uniform"), "start"),
    (dict(grad_clip=0.0), "grad_clip"), (dict(nu=-0.5), "nu"),
    (dict(grad_clip=1.0, grad_clip_mode="global"), "grad_clip_mode"),
])
def test_bad_arguments_raise(bad, field):
    critics, actor, obs = _nets()
    mean, log_std = actor(obs)
    kw = dict(steps=3, step_size=1e-3, temperature=0.1, nu=0.0) | bad
    with pytest.raises(ValueError, match=field):
        chain(critics, obs, mean, log_std, **kw)
    with pytest.raises(ValueError, match="noise"):
        chain(critics, obs, mean, log_std, steps=3, step_size=1e-3, temperature=0.1,
                       nu=0.0, noise=torch.zeros(3, B, ACT, dtype=D64))
