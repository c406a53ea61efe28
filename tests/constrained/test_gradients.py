"""constrained/gradients.py: RLlib's NaN/inf gradient guard in one test per step, the same update."""

import copy
import logging

import torch
from ray.rllib.core import DEFAULT_MODULE_ID

from lac_rllib.algorithms.sac_lag.config import SACLagConfig
from lac_rllib.constrained.gradients import clip_global_norm_, clip_global_norms_, polyak_, zero_non_finite_
from lac_rllib.tasks import get_task


def test_finite_gradients_are_left_as_they_are():
    grads = {"a": torch.randn(3, 4), "b": torch.randn(5), "none": None}
    before = dict(grads)
    assert zero_non_finite_(grads) == []
    assert all(grads[k] is before[k] for k in grads)


def test_a_finite_gradient_whose_norm_overflows_is_left_as_it_is():
    big = torch.full((1000,), 3e37)  # finite, but its L2 norm overflows float32
    assert not torch.isfinite(torch.linalg.vector_norm(big))
    grads = {"big": big, "small": torch.ones(2)}
    assert zero_non_finite_(grads) == [] and grads["big"] is big


def test_non_finite_gradients_become_what_torch_learner_makes_of_them(caplog):
    bad = torch.tensor([1.0, float("nan"), float("inf"), -float("inf")])
    good = torch.randn(3)
    grads = {"bad": bad, "good": good}
    with caplog.at_level(logging.WARNING):
        assert zero_non_finite_(grads) == ["bad"]
    torch.testing.assert_close(grads["bad"], torch.nan_to_num(bad))
    assert grads["good"] is good
    assert "bad" in caplog.text


def test_the_clips_finiteness_check_is_the_guards():
    """clip_global_norms_'s check, handed to zero_non_finite_, decides as the guard's own."""
    bad = torch.tensor([1.0, float("nan")])
    for grads, finite_expected in (([torch.randn(3), torch.randn(2, 2)], True), ([torch.randn(3), bad.clone()], False)):
        finite = []
        clip_global_norms_([grads[:1], grads[1:]], 0.5, finite)
        assert len(finite) == 1 and bool(finite[0]) is finite_expected
        as_dict = dict(enumerate(grads))
        assert zero_non_finite_(as_dict, finite[0]) == ([] if finite_expected else [1])
        assert all(torch.isfinite(g).all() for g in as_dict.values())
    # a check that says finite is trusted (the caller's promise: the clip saw these gradients)
    assert zero_non_finite_({0: bad.clone()}, torch.tensor(True)) == []



def test_the_step_equals_rllibs_own_guard_with_one_nan_gradient(one_torch_thread):
    """Our default (RLlib's per-tensor tests off, ours on) against RLlib's guard: the same weights
    after a step where one tensor's gradient is NaN and the others are finite."""
    def learner(rllib_guard: bool):
        config = SACLagConfig.build("lac/PointHazard-v0", 0, {"actor_hidden": (16, 16), "critic_hidden": (16, 16)})
        assert config.torch_skip_nan_gradients  # the default: ours only
        config.torch_skip_nan_gradients = not rllib_guard
        return config.build_learner(env=get_task("lac/PointHazard-v0").make({}))

    ours, rllib = learner(rllib_guard=False), learner(rllib_guard=True)
    rllib.set_state(ours.get_state())
    for learner in (ours, rllib):
        module = learner.module[DEFAULT_MODULE_ID]
        params = list(learner.get_parameters(module.reward_critics))
        gen = torch.Generator().manual_seed(0)
        grads = {learner.get_param_ref(p): torch.randn(p.shape, generator=gen) for p in params}
        first = learner.get_param_ref(params[0])
        grads[first] = torch.full_like(grads[first], float("nan"))
        learner.apply_gradients(grads)
    for a, b in zip(ours.module[DEFAULT_MODULE_ID].reward_critics.parameters(),
                    rllib.module[DEFAULT_MODULE_ID].reward_critics.parameters()):
        assert torch.isfinite(a).all()
        assert torch.equal(a, b)


def test_the_global_norm_clip_is_rllibs_bit_for_bit():
    """clip_global_norm_ against RLlib's clip_gradients(grad_clip_by="global_norm") on gradients
    from 1e-3 to 1e3 in scale (clipped and not), returning the same norm."""
    from ray.rllib.utils.torch_utils import clip_gradients

    gen = torch.Generator().manual_seed(0)
    clipped = 0
    for trial in range(60):
        shapes = [(64, 60), (64,), (64, 64), (64,), (4, 64), (4,)]
        grads = [torch.randn(s, generator=gen) * 10.0 ** (trial % 7 - 3) for s in shapes]
        ref = {i: g.clone() for i, g in enumerate(grads)}
        ours = [g.clone() for g in grads]
        ref_norm = clip_gradients(ref, grad_clip=0.5, grad_clip_by="global_norm")
        norm = clip_global_norm_(ours, 0.5)
        assert torch.equal(norm, ref_norm)
        assert all(torch.equal(a, b) for a, b in zip(ref.values(), ours))
        # Per group in one pass (one optimizer's gradients each): each group's own clip.
        split = [[g.clone() for g in grads[:2]], [g.clone() for g in grads[2:]]]
        refs = [{i: g.clone() for i, g in enumerate(part)} for part in split]
        ref_norms = [clip_gradients(r, grad_clip=0.5, grad_clip_by="global_norm") for r in refs]
        assert all(torch.equal(a, b) for a, b in zip(clip_global_norms_(split, 0.5), ref_norms))
        assert all(torch.equal(a, b) for r, part in zip(refs, split) for a, b in zip(r.values(), part))
        clipped += bool(norm > 0.5)
    assert 0 < clipped < 60  # both sides of the bound were exercised


def test_polyak_is_rllibs_update_target_network_bit_for_bit():
    from ray.rllib.utils.torch_utils import update_target_network

    torch.manual_seed(0)
    make = lambda: torch.nn.Sequential(torch.nn.Linear(9, 32), torch.nn.ReLU(), torch.nn.Linear(32, 1))  # noqa: E731
    mains, targets = [make(), make()], [make(), make()]
    ours = [copy.deepcopy(t) for t in targets]
    for _ in range(20):
        for m, t in zip(mains, targets):
            update_target_network(main_net=m, target_net=t, tau=0.005)
        polyak_(zip(mains, ours), 0.005)
        with torch.no_grad():
            for m in mains:
                for p in m.parameters():
                    p.add_(torch.randn_like(p))
    for t, o in zip(targets, ours):
        assert all(torch.equal(a, b) for a, b in zip(t.parameters(), o.parameters()))
    assert not torch.equal(next(targets[0].parameters()), next(make().parameters()))
