"""The KL of the policy to a reference policy, per state, and the trust-region indicator: the
terms FOCOPS (Zhang et al. 2020, eq. 11) and CUP's projection stage (Yang et al. 2022, eq. 9) add
to their surrogate. Plain torch, no RLlib: the distributions come in as a class with RLlib's
``from_logits``/``kl`` interface (``TorchDiagGaussian``: the KL summed over action dimensions, as
OmniSafe's ``kl_divergence(...).sum(-1)``)."""

from __future__ import annotations

import torch


def kl_to_reference(dist_cls, logits: torch.Tensor, reference_logits: torch.Tensor) -> torch.Tensor:
    """KL(π_θ(·|s) ‖ π_ref(·|s)) per row (B,): the policy's distribution inputs ``logits`` first,
    the reference's (held fixed: no gradient flows into it) second. A diagonal Gaussian's in closed
    form on its inputs [mean, log σ] (:func:`gaussian_kl`: no distribution objects per minibatch),
    any other distribution's by its ``kl``."""
    if getattr(dist_cls, "__name__", "") == "TorchDiagGaussian":
        return gaussian_kl(logits, reference_logits.detach())
    return dist_cls.from_logits(logits).kl(dist_cls.from_logits(reference_logits.detach()))


def gaussian_kl(logits: torch.Tensor, reference_logits: torch.Tensor) -> torch.Tensor:
    """KL(N(μ, σ²) ‖ N(μ_r, σ_r²)) summed over the action dimensions, from [μ, log σ] inputs:
    ½·(σ²/σ_r² + (μ − μ_r)²/σ_r² − 1 − log(σ²/σ_r²)) per dimension, torch's Normal–Normal KL op for
    op (what RLlib's TorchDiagGaussian.kl sums)."""
    mean, log_std = logits.chunk(2, dim=-1)
    ref_mean, ref_log_std = reference_logits.chunk(2, dim=-1)
    scale, ref_scale = log_std.exp(), ref_log_std.exp()
    var_ratio = (scale / ref_scale).pow(2)
    t1 = ((mean - ref_mean) / ref_scale).pow(2)
    return (0.5 * (var_ratio + t1 - 1 - var_ratio.log())).sum(-1)


def within(kl: torch.Tensor, eta: float) -> torch.Tensor:
    """FOCOPS's indicator 1[KL ≤ η] per row as a float (no gradient): a state whose policy has
    already moved more than η from the reference drops out of the loss [F, O focops.py]."""
    return (kl.detach() <= eta).to(kl.dtype)
