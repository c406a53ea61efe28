"""ForeachAdam (lac_rllib/families/on_policy/optim.py) is torch.optim.Adam's per-tensor loop, bit for bit."""

import copy

import pytest
import torch

from lac_rllib.families.on_policy.optim import ForeachAdam, step_adams


def _nets(seed=0):
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(12, 64), torch.nn.Tanh(), torch.nn.Linear(64, 64), torch.nn.Tanh(),
                              torch.nn.Linear(64, 3))
    return net, copy.deepcopy(net)


@pytest.mark.parametrize("tensor_lr", [True, False])
def test_the_same_weights_and_moments_as_the_per_tensor_loop(tensor_lr):
    """300 steps with a decaying rate (a 0-d float32 tensor, as RLlib's scheduler sets it, or a
    float), some steps leaving one layer without a gradient (its step count then lags): every
    weight, moment and step count equal to torch.optim.Adam(foreach=False)'s, bit for bit."""
    ref_net, net = _nets()
    ref, ours = torch.optim.Adam(ref_net.parameters(), lr=3e-4, foreach=False), ForeachAdam(net.parameters(), lr=3e-4)
    gen = torch.Generator().manual_seed(1)
    for step in range(300):
        lr = 3e-4 * (1 - step / 600)
        x = torch.randn(64, 12, generator=gen) * (1 + step % 7)
        for model, opt in ((ref_net, ref), (net, ours)):
            for g in opt.param_groups:
                g["lr"] = torch.tensor(lr) if tensor_lr else lr
            opt.zero_grad(set_to_none=True)
            model(x).pow(2).mean().backward()
            if step % 5 == 0:  # a frozen layer: Adam skips it, moments and count included
                model[2].weight.grad = None
            opt.step()
    for a, b in zip(ref_net.parameters(), net.parameters()):
        assert torch.equal(a, b)
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(ref.state[a][key], ours.state[b][key]), key
    assert int(ours.state[net[2].weight]["step"]) == 240 and int(ours.state[net[0].weight]["step"]) == 300


def test_a_float_rate_with_torch_foreach_would_round_differently():
    """Why not foreach=True with the rate cast to float: the tensor rate's float32 step size
    differs, so every seeded run would change (the reason ForeachAdam exists)."""
    ref_net, net = _nets()
    ref, other = (torch.optim.Adam(ref_net.parameters(), foreach=False),
                  torch.optim.Adam(net.parameters(), foreach=True))
    x = torch.randn(64, 12)
    for _ in range(20):
        for model, opt, lr in ((ref_net, ref, torch.tensor(2.9e-4)), (net, other, float(torch.tensor(2.9e-4)))):
            for g in opt.param_groups:
                g["lr"] = lr
            opt.zero_grad()
            model(x).pow(2).mean().backward()
            opt.step()
    assert not all(torch.equal(a, b) for a, b in zip(ref_net.parameters(), net.parameters()))


def test_state_dict_round_trips_into_torch_adam():
    """Checkpoints: ForeachAdam's state_dict is torch.optim.Adam's (a run restored either way
    continues the same)."""
    _, net = _nets()
    ours = ForeachAdam(net.parameters(), lr=1e-3)
    net(torch.randn(8, 12)).sum().backward()
    ours.step()
    plain = torch.optim.Adam(net.parameters(), lr=1e-3)
    plain.load_state_dict(ours.state_dict())
    assert int(plain.state_dict()["state"][0]["step"]) == 1
    ours.param_groups[0]["amsgrad"] = True  # a variant it does not implement is refused, not ignored
    with pytest.raises(ValueError, match="plain Adam only"):
        ours.step()


def test_several_optimizers_in_one_pass_are_each_their_own_adam():
    """step_adams over three optimizers (their own rates, one a tensor, one with other betas, one
    stepped less often) leaves every weight as three torch.optim.Adam stepping in turn."""
    torch.manual_seed(3)
    nets = [torch.nn.Linear(6, 5), torch.nn.Linear(5, 4), torch.nn.Linear(4, 1)]
    twins = copy.deepcopy(nets)
    settings = [dict(lr=1e-3), dict(lr=3e-4, betas=(0.8, 0.99)), dict(lr=5e-3)]
    refs = [torch.optim.Adam(n.parameters(), foreach=False, **kw) for n, kw in zip(nets, settings)]
    ours = [ForeachAdam(n.parameters(), **kw) for n, kw in zip(twins, settings)]
    for step in range(50):
        x = torch.randn(32, 6)
        for models, opts in ((nets, refs), (twins, ours)):
            for o in opts:
                o.zero_grad(set_to_none=True)
            opts[1].param_groups[0]["lr"] = torch.tensor(3e-4 / (1 + step))
            models[2](torch.tanh(models[1](torch.tanh(models[0](x))))).pow(2).mean().backward()
            if step % 3:
                for p in models[2].parameters():
                    p.grad = None
        for o in refs:
            o.step()
        step_adams(ours)
    for a, b in zip(nets, twins):
        assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
