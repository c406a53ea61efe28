"""RLlib's non-finite gradient guard, checked once per gradient step instead of once per tensor.

TorchLearner.apply_gradients (ray 2.60) tests ``torch.isfinite(grad).all()`` for every parameter's
gradient, and again for every parameter before each optimizer's step: each test reads its result
back to Python. At the baselines' network sizes that is 9% of a SAC-Lag gradient step and ~5% of a
PPO-Lag one (cProfile, PointGoal1 presets: docs/speed.md). Our configs set RLlib's
``torch_skip_nan_gradients`` (which only skips those tests) and our learners call
:func:`zero_non_finite_` before ``super().apply_gradients``: one test over all gradients, and where
it fails RLlib's own treatment, ``torch.nan_to_num`` of each non-finite gradient with RLlib's
warning. For finite gradients (every step of a healthy run) the update is the same, bit for bit.

Plain torch, no RLlib.
"""

from __future__ import annotations

import logging

import torch

logger = logging.getLogger(__name__)


@torch.no_grad()
def zero_non_finite_(gradients_dict: dict) -> list:
    """Replace, in ``gradients_dict``, each gradient with a NaN or inf by ``torch.nan_to_num`` of it
    (NaN → 0, ±inf → the largest finite float: RLlib's default); the keys replaced (usually none).

    The common case costs one read-back: the joint check of all gradients' norms. A norm is
    non-finite if its tensor is, and may also overflow for a finite one, so a failed joint check
    looks at each tensor before touching it."""
    grads = [g for g in gradients_dict.values() if g is not None]
    if not grads or bool(torch.stack(torch._foreach_norm(grads)).isfinite().all()):
        return []
    bad = [ref for ref, g in gradients_dict.items() if g is not None and not bool(torch.isfinite(g).all())]
    for ref in bad:
        gradients_dict[ref] = torch.nan_to_num(gradients_dict[ref])
    if bad:
        logger.warning("Gradients %s contain nan/inf values; set to finite values (torch.nan_to_num), as "
                       "RLlib's TorchLearner does.", bad)
    return bad
