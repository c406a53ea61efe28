"""The KL of the policy to a reference policy, per state, and the trust-region indicator: the
terms FOCOPS (Zhang et al. 2020, eq. 11) and CUP's projection stage (Yang et al. 2022, eq. 9) add
to their surrogate. Plain torch, no RLlib: the distributions come in as a class with RLlib's
``from_logits``/``kl`` interface (``TorchDiagGaussian``: the KL summed over action dimensions, as
OmniSafe's ``kl_divergence(...).sum(-1)``)."""

from __future__ import annotations

import torch


def kl_to_reference(dist_cls, logits: torch.Tensor, reference_logits: torch.Tensor) -> torch.Tensor:
    """KL(π_θ(·|s) ‖ π_ref(·|s)) per row (B,): the policy's distribution inputs ``logits`` first,
    the reference's (held fixed: no gradient flows into it) second."""
    return dist_cls.from_logits(logits).kl(dist_cls.from_logits(reference_logits.detach()))


def within(kl: torch.Tensor, eta: float) -> torch.Tensor:
    """FOCOPS's indicator 1[KL ≤ η] per row as a float (no gradient): a state whose policy has
    already moved more than η from the reference drops out of the loss [F, O focops.py]."""
    return (kl.detach() <= eta).to(kl.dtype)
