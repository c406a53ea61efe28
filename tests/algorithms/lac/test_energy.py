"""The LAC energy (lac_rllib.algorithms.lac.energy): the compiled step equals the eager chain, the
bfloat16 matmuls move end points by far less than the chain's own noise, and a failed compile
falls back to the exact eager path."""

import logging
import math

import pytest
import torch
from conftest import chain

from lac_rllib.algorithms.lac import energy as energy_module
from lac_rllib.constrained.networks import CriticEnsemble, GaussianActor

ETA = 1e-4


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _case(obs_dim=9, act_dim=3, batch=64, hidden=(64, 64, 64), activation="mish", seed=0, steps=30):
    torch.manual_seed(seed)
    critics = CriticEnsemble(obs_dim, act_dim, hidden=hidden, activation=activation)
    actor = GaussianActor(obs_dim, act_dim)
    obs = torch.randn(batch, obs_dim)
    with torch.no_grad():
        mean, log_std = actor(obs)
    kw = dict(steps=steps, step_size=ETA, temperature=1e-3, nu=torch.tensor(0.7),
              noise=torch.randn(steps + 1, batch, act_dim), low=-torch.ones(act_dim), high=torch.ones(act_dim))
    return critics, obs, mean, log_std, kw


@pytest.mark.parametrize("activation", ["mish", "tanh", "relu"])
@pytest.mark.parametrize("clip", [None, 1000.0])
def test_pure_function_equals_the_hand_written_backward(activation, clip):
    critics, obs, mean, log_std, kw = _case(activation=activation)
    ref = chain(critics, obs, mean, log_std, grad_clip=clip, **kw)
    grad_fn = energy_module.make_grad_fn(critics, critics.project_state(obs), mean, log_std, temperature=1e-3,
                                        nu=0.7, logp_weight=1.0, compiled=False)
    energy, grad = grad_fn(ref.action)
    with torch.enable_grad():  # autograd through the full critics as the judge
        a = ref.action.clone().requires_grad_(True)
        q = critics(obs, a)
        logp = torch.distributions.Normal(mean, log_std.exp()).log_prob(a).sum(-1)
        e = (0.7 * q[2:].max(0).values - q[:2].min(0).values) / 1e-3 - logp
        (g,) = torch.autograd.grad(e.sum(), a)
    torch.testing.assert_close(energy, e.detach(), rtol=1e-5, atol=1e-3)
    torch.testing.assert_close(grad, g, rtol=1e-4, atol=1e-3)
    torch.testing.assert_close(energy, ref.energy_end, rtol=1e-5, atol=1e-3)


def test_compiled_chain_equals_eager_chain():
    critics, obs, mean, log_std, kw = _case()
    eager = chain(critics, obs, mean, log_std, grad_clip=1000.0, **kw)
    fused = chain(critics, obs, mean, log_std, grad_clip=1000.0, fused=True, **kw)
    assert not energy_module._compile_failed, "torch.compile fell back to eager: nothing was compared"
    torch.testing.assert_close(fused.action, eager.action, rtol=0, atol=1e-5)
    torch.testing.assert_close(fused.energy_end, eager.energy_end, rtol=1e-5, atol=1e-2)
    torch.testing.assert_close(fused.grad_norm, eager.grad_norm, rtol=1e-5, atol=0)
    assert fused.clip_fraction == eager.clip_fraction and fused.at_bound == eager.at_bound


def test_bfloat16_end_points_differ_by_far_less_than_the_chain_noise():
    """Same critics, same noise: bf16 matmuls may move ã_T, but on average by far less than one
    step's noise √η, and nowhere by more than it (the whole chain's noise √(Tη) is 5.5x that).
    Measured here: mean |Δa| ≈ 0.003·√η, max ≈ 0.3·√η (where a critic's argmin flips)."""
    diffs, moves = [], []
    for seed in range(3):
        critics, obs, mean, log_std, kw = _case(obs_dim=60, act_dim=2, batch=128, hidden=(256, 256, 256), seed=seed)
        f32 = chain(critics, obs, mean, log_std, grad_clip=1000.0, **kw)
        bf16 = chain(critics, obs, mean, log_std, grad_clip=1000.0, dtype="bfloat16", **kw)
        diffs.append((bf16.action - f32.action).abs())
        moves.append(f32.displacement)
    diff = torch.cat([d.flatten() for d in diffs])
    sqrt_eta = math.sqrt(ETA)
    assert diff.mean() < 0.05 * sqrt_eta, f"mean |Δa| {diff.mean():.2e} vs √η {sqrt_eta:.0e}"
    assert diff.max() < sqrt_eta, f"max |Δa| {diff.max():.2e} vs √η {sqrt_eta:.0e}"
    # The comparison means something: the chains moved by much more than they disagree.
    assert torch.cat(moves).mean() > 20 * diff.mean()
    assert diff.max() > 0, "bfloat16 changed nothing: were the matmuls run in bfloat16 at all?"


def test_a_failed_compile_falls_back_to_the_eager_path(monkeypatch, caplog):
    critics, obs, mean, log_std, kw = _case()

    def broken(*args, **kwargs):
        raise RuntimeError("no C++ compiler")

    monkeypatch.setattr(energy_module, "_compiled", broken)
    monkeypatch.setattr(energy_module, "_compile_failed", False)
    with caplog.at_level(logging.WARNING, logger=energy_module.__name__):
        fused = chain(critics, obs, mean, log_std, fused=True, **kw)
    eager = chain(critics, obs, mean, log_std, **kw)
    assert energy_module._compile_failed
    assert "no C++ compiler" in caplog.text
    torch.testing.assert_close(fused.action, eager.action, rtol=0, atol=1e-5)


def test_unknown_dtype_is_refused():
    critics, obs, mean, log_std, kw = _case()
    with pytest.raises(ValueError, match="float16.*accepted: float32 | bfloat16"):
        chain(critics, obs, mean, log_std, dtype="float16", **kw)


def test_auto_dtype_is_bfloat16_only_with_native_bf16_matmuls(monkeypatch):
    import gymnasium as gym

    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.algorithms.lac.module import chain_settings
    from lac_rllib.constrained import precision

    cfg = {**LACConfig().training(langevin_dtype="auto").params()}
    space = gym.spaces.Box(-1.0, 1.0, (2,))
    for flags, expected in (({"avx2", "avx512f"}, "float32"), ({"avx2", "avx512_bf16"}, "bfloat16"),
                            ({"amx_bf16"}, "bfloat16"), (set(), "float32")):
        monkeypatch.setattr(precision, "cpu_flags", lambda flags=flags: flags)
        assert precision.resolve_dtype("auto") == expected
        assert chain_settings(cfg, space).dtype == expected  # decided where the module is built
    assert precision.resolve_dtype("float32") == "float32"  # an explicit dtype is kept


def _two_constraints(seed=0, batch=64, steps=20):
    """An ensemble of 2 reward and 2 × 2 cost critics (two constraints, twin critics each), ν (2,)."""
    torch.manual_seed(seed)
    critics = CriticEnsemble(9, 3, hidden=(64, 64, 64), n_cost=4)
    actor = GaussianActor(9, 3)
    obs = torch.randn(batch, 9)
    with torch.no_grad():
        mean, log_std = actor(obs)
    nu = torch.tensor([0.7, 2.5])
    kw = dict(steps=steps, step_size=ETA, temperature=1e-3, nu=nu, noise=torch.randn(steps + 1, batch, 3),
              low=-torch.ones(3), high=torch.ones(3))
    return critics, obs, mean, log_std, nu, kw


@pytest.mark.parametrize("compiled", [False, True])
def test_with_two_constraints_the_energy_weighs_each_ones_max_by_its_nu(compiled):
    """E = (Σ_k ν_k·max_j Q_Ckj − min_j Q_Rj)/λ − log π, its action gradient the same as autograd's,
    on both paths (the compiled one the chain of every navigation preset)."""
    critics, obs, mean, log_std, nu, kw = _two_constraints()
    ref = chain(critics, obs, mean, log_std, grad_clip=1000.0, **kw)
    grad_fn = energy_module.make_grad_fn(critics, critics.project_state(obs), mean, log_std, temperature=1e-3,
                                        nu=nu, logp_weight=1.0, compiled=compiled)
    energy, grad = grad_fn(ref.action)
    assert not energy_module._compile_failed, "torch.compile fell back to eager: nothing was compared"
    with torch.enable_grad():
        a = ref.action.clone().requires_grad_(True)
        q = critics(obs, a)
        logp = torch.distributions.Normal(mean, log_std.exp()).log_prob(a).sum(-1)
        cost = 0.7 * q[2:4].max(0).values + 2.5 * q[4:6].max(0).values
        e = (cost - q[:2].min(0).values) / 1e-3 - logp
        (g,) = torch.autograd.grad(e.sum(), a)
    torch.testing.assert_close(energy, e.detach(), rtol=1e-5, atol=1e-3)
    torch.testing.assert_close(grad, g, rtol=1e-4, atol=1e-3)
    # one ν for both constraints would be another energy: the test can tell them apart
    assert not torch.allclose(energy, ((1.6 * q[2:].max(0).values - q[:2].min(0).values) / 1e-3 - logp).detach(),
                              rtol=1e-5, atol=1e-3)


def test_with_two_constraints_the_bfloat16_chain_runs_and_stays_near_float32():
    critics, obs, mean, log_std, nu, kw = _two_constraints()
    f32 = chain(critics, obs, mean, log_std, grad_clip=1000.0, fused=True, **kw)
    bf16 = chain(critics, obs, mean, log_std, grad_clip=1000.0, fused=True, dtype="bfloat16", **kw)
    assert torch.isfinite(bf16.action).all() and (bf16.action - f32.action).abs().max() < 0.05
