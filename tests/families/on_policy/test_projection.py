"""families/on_policy/projection.py: the KL to a reference policy and FOCOPS's indicator."""

import torch
from ray.rllib.core.distribution.torch.torch_distribution import TorchDiagGaussian

from lac_rllib.families.on_policy.projection import gaussian_kl, kl_to_reference, within


def test_the_closed_form_gaussian_kl_is_rllibs_bit_for_bit_with_its_gradient():
    gen = torch.Generator().manual_seed(0)
    logits = torch.randn(64, 6, generator=gen).requires_grad_(True)
    reference = torch.randn(64, 6, generator=gen)
    ours = kl_to_reference(TorchDiagGaussian, logits, reference)
    rllib_logits = logits.detach().clone().requires_grad_(True)
    theirs = TorchDiagGaussian.from_logits(rllib_logits).kl(TorchDiagGaussian.from_logits(reference))
    assert torch.equal(ours, theirs) and torch.equal(ours, gaussian_kl(logits, reference))
    ours.sum().backward()
    theirs.sum().backward()
    torch.testing.assert_close(logits.grad, rllib_logits.grad, rtol=1e-6, atol=1e-7)
    ref = reference.clone().requires_grad_(True)
    assert not kl_to_reference(TorchDiagGaussian, logits.detach(), ref).requires_grad  # the reference held fixed


def test_the_indicator_drops_rows_past_eta_without_a_gradient():
    kl = torch.tensor([0.01, 0.02, 0.03], requires_grad=True)
    inside = within(kl, 0.02)
    assert inside.tolist() == [1.0, 1.0, 0.0] and not inside.requires_grad
