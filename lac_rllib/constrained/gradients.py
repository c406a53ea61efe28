"""What every learner does to gradients and weights between the backward pass and the next step:
RLlib's non-finite gradient guard (checked once per step), the global-norm clip and Polyak averaging.

The guard:
TorchLearner.apply_gradients (ray 2.60) tests ``torch.isfinite(grad).all()`` for every parameter's
gradient, and again for every parameter before each optimizer's step: each test reads its result
back to Python. At the baselines' network sizes that is 9% of a SAC-Lag gradient step and ~5% of a
PPO-Lag one (cProfile, PointGoal1 presets: docs/speed.md). Our configs set RLlib's
``torch_skip_nan_gradients`` (which only skips those tests) and our learners call
:func:`zero_non_finite_` before ``super().apply_gradients``: one test over all gradients, and where
it fails RLlib's own treatment, ``torch.nan_to_num`` of each non-finite gradient with RLlib's
warning. For finite gradients (every step of a healthy run) the update is the same, bit for bit.
A learner that clips every gradient first hands the clip's joint check of the same norms to the
guard (PPO-Lag's house), so a step computes those norms once.

:func:`clip_global_norm_` and :func:`polyak_` are RLlib's ``clip_gradients(grad_clip_by=
"global_norm")`` and ``update_target_network`` in the same arithmetic, bit for bit
(tests/constrained/test_gradients.py), with torch's multi-tensor (foreach) ops: a few calls per
network instead of a few per tensor (RLlib's Polyak goes through two state dicts and a
``load_state_dict``). Every algorithm clips and averages through them.

Plain torch, no RLlib.
"""

from __future__ import annotations

import logging

import torch

logger = logging.getLogger(__name__)


@torch.no_grad()
def zero_non_finite_(gradients_dict: dict, finite: torch.Tensor | None = None) -> list:
    """Replace, in ``gradients_dict``, each gradient with a NaN or inf by ``torch.nan_to_num`` of it
    (NaN → 0, ±inf → the largest finite float: RLlib's default); the keys replaced (usually none).

    The common case costs one read-back: the joint check of all gradients' norms. A norm is
    non-finite if its tensor is, and may also overflow for a finite one, so a failed joint check
    looks at each tensor before touching it. ``finite``: that joint check already made on these
    gradients' norms (:func:`clip_global_norms_`'s, which scales by a finite factor at most 1 and
    so keeps finite gradients finite), its norms not computed again."""
    grads = [g for g in gradients_dict.values() if g is not None]
    if finite is None and grads:
        finite = torch.stack(torch._foreach_norm(grads)).isfinite().all()
    if not grads or bool(finite):
        return []
    bad = [ref for ref, g in gradients_dict.items() if g is not None and not bool(torch.isfinite(g).all())]
    for ref in bad:
        gradients_dict[ref] = torch.nan_to_num(gradients_dict[ref])
    if bad:
        logger.warning("Gradients %s contain nan/inf values; set to finite values (torch.nan_to_num), as "
                       "RLlib's TorchLearner does.", bad)
    return bad


@torch.no_grad()
def clip_global_norm_(grads: list, max_norm: float) -> torch.Tensor:
    """Scale ``grads`` in place so that their joint L2 norm is at most ``max_norm``; returns the
    norm before clipping. RLlib's global-norm clip (``clip_gradients``), the same arithmetic:
    coefficient ``max_norm / max(norm + 1e-6, max_norm)`` (≤ 1, exactly 1 below the bound), per-tensor
    norms (RLlib's and torch's ``clip_grad_norm_``'s) made non-finite-safe as RLlib does."""
    return clip_global_norms_([grads], max_norm)[0]


@torch.no_grad()
def clip_global_norms_(groups: list, max_norm: float, finite: list | None = None) -> list:
    """:func:`clip_global_norm_` of each group of gradients (one network's, one optimizer's) on its
    own, all groups in one pass: one foreach norm and one multiply over every tensor. ``finite``: a
    list to which the joint check of every tensor's norm is appended (a 0-d bool tensor, not read
    back), for :func:`zero_non_finite_` to reuse."""
    groups = [[g for g in grads if g is not None] for grads in groups]
    flat = [g for grads in groups for g in grads]
    if not flat:
        if finite is not None:
            finite.append(torch.tensor(True))
        return [torch.tensor(0.0) for _ in groups]
    norms = torch.stack(torch._foreach_norm(flat, 2.0))
    if finite is not None:
        finite.append(norms.isfinite().all())
    norms = norms.nan_to_num(neginf=-10e8, posinf=10e8)
    # Each group's total norm on its own, then the coefficient of every group in one vector of
    # element-wise ops (each element's arithmetic is the 0-d tensor's: no reduction crosses groups).
    totals, start = [], 0
    for grads in groups:
        totals.append(torch.linalg.vector_norm(norms[start:start + len(grads)], 2.0) if grads
                      else torch.zeros((), dtype=norms.dtype))
        start += len(grads)
    totals = torch.stack(totals).nan_to_num(neginf=-10e8, posinf=10e8)
    coefs = torch.clamp(max_norm / torch.clamp(totals + 1e-6, min=max_norm), max=1.0).unbind()
    torch._foreach_mul_(flat, [coef for coef, grads in zip(coefs, groups) for _ in grads])
    return list(totals.unbind())


@torch.no_grad()
def polyak_(pairs, tau: float) -> None:
    """θ' ← τ·θ + (1 − τ)·θ' for every (main, target) network pair, in place: RLlib's
    ``update_target_network`` formula and rounding (the two products, then their sum)."""
    mains, targets = [], []
    for main_net, target_net in pairs:
        mains.extend(main_net.parameters())
        targets.extend(target_net.parameters())
    if mains:
        scaled = torch._foreach_mul(mains, tau)
        torch._foreach_mul_(targets, 1 - tau)
        torch._foreach_add_(targets, scaled)
