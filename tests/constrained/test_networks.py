"""Networks: the batched critic ensemble must be E independent MLPs, and its manual action
gradient must equal autograd's; the Gaussian helpers must equal torch.distributions."""

import math

import pytest
import torch
from torch import nn

from lac_rllib.constrained.networks import (
    CriticEnsemble,
    GaussianActor,
    cost_rows,
    gaussian_kl,
    gaussian_log_prob,
    mlp,
    reward_rows,
)

OBS, ACT, HID = 5, 3, (16, 12, 8)
D64 = torch.float64


def _ensemble(activation="mish", seed=0):
    torch.manual_seed(seed)
    return CriticEnsemble(OBS, ACT, HID, n_reward=2, n_cost=2, activation=activation).to(D64)


def _inputs(batch=7, seed=1):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(batch, OBS, generator=g, dtype=D64),
            torch.randn(batch, ACT, generator=g, dtype=D64))


def _member_as_sequential(ens: CriticEnsemble, e: int) -> nn.Sequential:
    act = {"mish": nn.Mish, "tanh": nn.Tanh, "relu": nn.ReLU}[ens.activation]
    layers = []
    for k, (w, b) in enumerate(zip(ens.weights, ens.biases)):
        lin = nn.Linear(w.shape[1], w.shape[2]).to(D64)
        with torch.no_grad():
            lin.weight.copy_(w[e].t())
            lin.bias.copy_(b[e, 0])
        layers += [lin] + ([act()] if k < len(ens.weights) - 1 else [])
    return nn.Sequential(*layers)


def test_ensemble_layout_and_init_is_exactly_nn_linear():
    ens = CriticEnsemble(OBS, ACT, HID, n_reward=2, n_cost=3)
    assert (ens.n_reward, ens.n_cost) == (2, 3)
    dims = [OBS + ACT, *HID, 1]
    assert [tuple(w.shape) for w in ens.weights] == [(5, i, o) for i, o in zip(dims, dims[1:])]
    assert [tuple(b.shape) for b in ens.biases] == [(5, 1, o) for o in dims[1:]]
    # Same seed, E separately built nn.Linear stacks in member order → identical weights.
    torch.manual_seed(3)
    ens = CriticEnsemble(OBS, ACT, HID, n_reward=2, n_cost=2)
    torch.manual_seed(3)
    ref = [[nn.Linear(i, o) for i, o in zip(dims, dims[1:])] for _ in range(4)]
    for e in range(4):
        for k in range(len(dims) - 1):
            torch.testing.assert_close(ens.weights[k][e], ref[e][k].weight.t())
            torch.testing.assert_close(ens.biases[k][e, 0], ref[e][k].bias)
            bound = 1 / math.sqrt(dims[k])
            assert ens.weights[k][e].abs().max() <= bound and ens.biases[k][e].abs().max() <= bound
    # Members are independent draws, not copies.
    assert not torch.equal(ens.weights[0][0], ens.weights[0][1])


@pytest.mark.parametrize("activation", ["mish", "tanh", "relu"])
def test_forward_equals_independent_mlps(activation):
    ens = _ensemble(activation)
    obs, act = _inputs()
    q = ens(obs, act)
    assert q.shape == (4, 7)
    x = torch.cat([obs, act], -1)
    for e in range(4):
        torch.testing.assert_close(q[e], _member_as_sequential(ens, e)(x).squeeze(-1))
    # The named rows are views of q (no copy): [:n_reward] reward critics, [n_reward:] cost critics.
    assert reward_rows(q, 2).data_ptr() == q.data_ptr() and torch.equal(reward_rows(q, 2), q[:2])
    assert cost_rows(q, 2).data_ptr() == q[2:].data_ptr() and torch.equal(cost_rows(q, 2), q[2:])


def test_projection_then_q_equals_forward():
    ens = _ensemble()
    obs, act = _inputs()
    proj = ens.project_state(obs)
    assert proj.shape == (4, 7, HID[0])
    q, _ = ens.q_and_action_grad(proj, act, torch.zeros(4, 7))  # the chain's path to Q
    torch.testing.assert_close(q, ens(obs, act))


@pytest.mark.parametrize("activation", ["mish", "tanh", "relu"])
@pytest.mark.parametrize("scale", [1.0, 300.0])  # 300: pre-activations deep in both tails
def test_manual_action_grad_equals_autograd(activation, scale):
    ens = _ensemble(activation)
    obs, act = (scale * x for x in _inputs(batch=9))
    coef = torch.randn(4, 9, generator=torch.Generator().manual_seed(2), dtype=D64)
    a = act.clone().requires_grad_(True)
    (ref,) = torch.autograd.grad((coef * ens(obs, a)).sum(), a)
    q, grad = ens.q_and_action_grad(ens.project_state(obs), act, coef)
    torch.testing.assert_close(q, ens(obs, act))
    torch.testing.assert_close(grad, ref, rtol=1e-10, atol=1e-12)
    assert grad.shape == (9, ACT)
    # A callable coefficient sees the Q values (used by the chain's argmin/argmax selection).
    _, grad2 = ens.q_and_action_grad(ens.project_state(obs), act, lambda qq: coef * 0 + coef)
    torch.testing.assert_close(grad2, grad)


def test_manual_action_grad_builds_no_graph():
    ens = _ensemble()
    obs, act = _inputs()
    q, grad = ens.q_and_action_grad(ens.project_state(obs), act.requires_grad_(True),
                                    torch.ones(4, 7, dtype=D64))
    assert not q.requires_grad and not grad.requires_grad
    assert all(p.grad is None for p in ens.parameters())


def test_gaussian_actor_shapes_and_init():
    torch.manual_seed(0)
    actor = GaussianActor(OBS, ACT, hidden=(32, 32), log_std_init=-0.5)
    mean, log_std = actor(torch.randn(6, OBS))
    assert mean.shape == log_std.shape == (6, ACT)
    assert actor.log_std.shape == (ACT,)
    torch.testing.assert_close(log_std, torch.full((6, ACT), -0.5))
    n_linear = sum(isinstance(m, nn.Linear) for m in actor.mean_net)
    assert n_linear == 3 and isinstance(actor.mean_net[1], nn.Tanh)
    with pytest.raises(ValueError, match="activation"):
        mlp(3, (4,), 2, "gelu_typo")


def test_gaussian_log_prob_and_kl_match_torch_distributions():
    g = torch.Generator().manual_seed(0)
    mp, mq, a = (torch.randn(10, 4, generator=g, dtype=D64) for _ in range(3))
    lp, lq = (0.5 * torch.randn(10, 4, generator=g, dtype=D64) for _ in range(2))
    normal = torch.distributions.Normal
    ref_logp = normal(mp, lp.exp()).log_prob(a).sum(-1)
    torch.testing.assert_close(gaussian_log_prob(a, mp, lp), ref_logp)
    ref = torch.distributions.kl_divergence(normal(mp, lp.exp()), normal(mq, lq.exp())).sum(-1)
    torch.testing.assert_close(gaussian_kl(mp, lp, mq, lq), ref)
    torch.testing.assert_close(gaussian_kl(mp, lp, mp, lp), torch.zeros(10, dtype=D64))


def test_actor_mean_head_init_is_scaled_and_unbiased():
    torch.manual_seed(3)
    plain = GaussianActor(OBS, ACT, hidden=(32, 32))
    torch.manual_seed(3)
    small = GaussianActor(OBS, ACT, hidden=(32, 32), mean_init_scale=0.1)
    torch.testing.assert_close(small.mean_net[-1].weight, 0.1 * plain.mean_net[-1].weight)
    assert torch.count_nonzero(small.mean_net[-1].bias) == 0 and torch.count_nonzero(plain.mean_net[-1].bias) > 0
    torch.testing.assert_close(small.mean_net[0].weight, plain.mean_net[0].weight)  # the body is untouched


def test_bfloat16_hidden_layers_keep_q_and_the_gradients_float32():
    """SAC-Lag's critic_dtype: the hidden layers multiply in bfloat16, the output layer in float32,
    so Q and every parameter's gradient are float32 and within bfloat16's rounding of the float32
    ensemble's; the default float32 forward is the plain one."""
    torch.manual_seed(0)
    full = CriticEnsemble(OBS, ACT, (64, 64), n_reward=2, n_cost=1, activation="relu")
    half = CriticEnsemble(OBS, ACT, (64, 64), n_reward=2, n_cost=1, activation="relu", matmul_dtype=torch.bfloat16)
    half.load_state_dict(full.state_dict())
    g = torch.Generator().manual_seed(4)
    obs, act = torch.randn(256, OBS, generator=g), torch.randn(256, ACT, generator=g)
    q_full, q_half = full(obs, act), half(obs, act)
    assert q_half.dtype == torch.float32
    assert not torch.equal(q_full, q_half), "the hidden layers must have run in bfloat16"
    scale = q_full.abs().max()
    assert (q_half - q_full).abs().max() < 2e-2 * scale  # bfloat16's 8 bits, not an error of the maths
    q_full.square().sum().backward()
    q_half.square().sum().backward()
    for a, b in zip(full.parameters(), half.parameters()):
        assert b.grad.dtype == torch.float32
        cosine = torch.nn.functional.cosine_similarity(a.grad.flatten(), b.grad.flatten(), dim=0)
        assert cosine > 0.999, cosine
    with pytest.raises(ValueError, match=r"matmul_dtype=torch.float16; accepted: torch.float32, torch.bfloat16"):
        CriticEnsemble(OBS, ACT, (8,), matmul_dtype=torch.float16)
