"""The Langevin policy: Algorithm 1 of the paper, in the efficient form of docs/spec.md §1.

Algorithm 1 / eq. (9): for i = 1..T,

    ã_i = ã_{i-1} − (η/2)·∇_a E(s, ã_{i-1}) + √η·z_i,     z_i ~ N(0, I),

    E(s, a) = (1/λ)·(ν·max_j Q_Cj(s, a) − min_j Q_Rj(s, a)) − w·log π_φ'(a|s),

started from the target actor, ã_0 ~ π_φ'(·|s) (informative start, eq. 11), or from N(0, I)
(non-informative, the paper's NI ablation). Theorem 3.1: for an energy that is m-strongly convex
with l-Lipschitz gradient, the law of ã_T approaches exp(−E)/Z as η → 0, T → ∞.

Efficient form: only what depends on the action is recomputed per step. The critics' first-layer
state projection and the actor's (μ, σ) are computed once per chain; ∇_a log π is the Gaussian
closed form; the four critics run as one batched ensemble with a hand-written backward that
builds no autograd graph. ``naive_langevin_chain`` is the straightforward autograd reference
that tests and ``benchmarks/langevin.py`` compare against.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import torch

from lac_rllib.algorithms.lac.energy import eager_grad_fn, make_grad_fn
from lac_rllib.constrained.networks import CriticEnsemble, cost_rows, reward_rows
from lac_rllib.constrained.precision import DTYPES

GradFn = Callable[[torch.Tensor], "tuple[torch.Tensor, torch.Tensor]"]
# Where a chain starts (the ``langevin_start`` field): ã_0 ~ π_φ'(·|s) (eq. 11), or N(0, I) (NI).
INFORMATIVE, NONINFORMATIVE = "informative", "noninformative"
STARTS = (INFORMATIVE, NONINFORMATIVE)
# How ∇_a E is clipped (the ``langevin_grad_clip_mode`` field), see clip_grad.
CLIP_MODES = ("batch", "per_sample")


@dataclass
class ChainResult:
    action: torch.Tensor        # (B, A) ã_T, detached
    energy_start: torch.Tensor  # (B,) E(s, ã_0)
    energy_end: torch.Tensor    # (B,) E(s, ã_T)
    displacement: torch.Tensor  # (B,) ‖ã_T − ã_0‖₂
    # Chain health (scalars): is the chain doing what the paper intends, or is it pinned at the
    # bounds / throttled by the clip?
    grad_norm: torch.Tensor     # mean over steps and samples of ‖∇_a E‖₂, before the clip
    clip_fraction: torch.Tensor  # fraction of steps (batch mode) / sample-steps (per sample) clipped
    at_bound: torch.Tensor      # fraction of end points with a coordinate on (or past) a bound


def clip_grad(grad: torch.Tensor, clip: float, mode: str = "batch") -> tuple[torch.Tensor, torch.Tensor]:
    """Clip ∇_a E (B, A) → (clipped, clipped? as float: () in batch mode, (B,) per sample).

    "batch" [C]: one L2 norm over the whole (B × A) tensor, scaled to at most ``clip``: every
    sample's step shrinks by the same factor. "per_sample" [D]: each row to ``clip/√B``, the
    same length when the rows are alike, without one wild sample shrinking everyone's step.
    """
    if mode == "batch":
        norm = torch.linalg.vector_norm(grad)
        scale = (clip / norm.clamp_min(1e-12)).clamp(max=1.0)
        return grad * scale, (scale < 1.0).to(grad.dtype)
    if mode == "per_sample":
        bound = clip / math.sqrt(grad.shape[0])
        norm = torch.linalg.vector_norm(grad, dim=-1, keepdim=True)
        scale = (bound / norm.clamp_min(1e-12)).clamp(max=1.0)
        return grad * scale, (scale.squeeze(-1) < 1.0).to(grad.dtype)
    raise ValueError(f"grad_clip_mode={mode!r}; accepted: {' | '.join(CLIP_MODES)}")


def _as_bound(x, like: torch.Tensor):
    return None if x is None else torch.as_tensor(x, dtype=like.dtype, device=like.device)


def _check_chain_args(steps: int, step_size: float, grad_clip, grad_clip_mode: str = "batch") -> None:
    if not (isinstance(steps, int) and steps >= 1):
        raise ValueError(f"steps={steps!r}; must be an integer ≥ 1")
    if not step_size > 0:
        raise ValueError(f"step_size={step_size!r}; must be > 0")
    if grad_clip is not None and not grad_clip > 0:
        raise ValueError(f"grad_clip={grad_clip!r}; must be > 0 or None")
    if grad_clip_mode not in CLIP_MODES:
        raise ValueError(f"grad_clip_mode={grad_clip_mode!r}; accepted: {' | '.join(CLIP_MODES)}")


@torch.no_grad()
def run_chain(grad_fn: GradFn, a0: torch.Tensor, *, steps: int, step_size: float,
              noise: torch.Tensor | None = None, generator: torch.Generator | None = None,
              low=None, high=None, grad_clip: float | None = None,
              grad_clip_mode: str = "batch") -> ChainResult:
    """Generic unadjusted Langevin chain (eq. 9); ``grad_fn(a) -> (E (B,), ∇_a E (B, A))``.

    ``grad_clip`` (None = off) bounds ∇_a E at every step as :func:`clip_grad` says.
    """
    _check_chain_args(steps, step_size, grad_clip, grad_clip_mode)
    if noise is not None and noise.shape != (steps, *a0.shape):
        raise ValueError(f"noise.shape={tuple(noise.shape)}; expected {(steps, *a0.shape)}")
    low, high = _as_bound(low, a0), _as_bound(high, a0)
    half_eta, sqrt_eta = 0.5 * step_size, math.sqrt(step_size)
    a0 = a0.detach()
    a, energy_start = a0, None
    norm_sum = torch.zeros((), dtype=a0.dtype, device=a0.device)
    clipped_sum = torch.zeros((), dtype=a0.dtype, device=a0.device)
    for i in range(steps):
        energy, grad = grad_fn(a)
        if i == 0:
            energy_start = energy
        norm_sum += torch.linalg.vector_norm(grad, dim=-1).mean()
        if grad_clip is not None:
            grad, clipped = clip_grad(grad, grad_clip, grad_clip_mode)
            clipped_sum += clipped.mean()
        z = noise[i] if noise is not None else torch.randn(
            a.shape, generator=generator, dtype=a.dtype, device=a.device)
        a = a - half_eta * grad + sqrt_eta * z
        if low is not None or high is not None:
            a = torch.clamp(a, min=low, max=high)  # [C] keeps the chain inside the action box
    energy_end, _ = grad_fn(a)
    on_bound = torch.zeros(a.shape[0], dtype=torch.bool, device=a.device)
    if low is not None:
        on_bound |= (a <= low).any(-1)
    if high is not None:
        on_bound |= (a >= high).any(-1)
    return ChainResult(action=a.detach(), energy_start=energy_start, energy_end=energy_end,
                       displacement=(a - a0).norm(dim=-1), grad_norm=norm_sum / steps,
                       clip_fraction=clipped_sum / steps, at_bound=on_bound.to(a.dtype).mean())


@dataclass(frozen=True, eq=False)
class ChainSettings:
    """Algorithm 1's settings, checked once when made (``LACTorchRLModule`` makes one from its
    config at setup; ``dataclasses.replace`` gives a variant, e.g. another T for evaluation).
    The fields are those of ``LACParams`` (docs/config.md) without the ``langevin_`` prefix."""

    steps: int  # T
    step_size: float  # η
    temperature: float  # λ
    logp_weight: float = 1.0  # w
    start: str = INFORMATIVE  # ã₀ ~ π_φ'(·|s) (eq. 11), or N(0, I) (NI)
    low: torch.Tensor | None = None  # action bounds the chain is clamped to after every step (None: free)
    high: torch.Tensor | None = None
    grad_clip: float | None = None  # clip of ∇_a E at every step (None: off), see clip_grad
    grad_clip_mode: str = "batch"
    fused: bool = False  # each step's energy gradient through torch.compile (energy.make_grad_fn)
    dtype: str = "float32"  # the critics' matmul inputs: "float32" | "bfloat16"

    def __post_init__(self):
        _check_chain_args(self.steps, self.step_size, self.grad_clip, self.grad_clip_mode)
        if not self.temperature > 0:
            raise ValueError(f"temperature={self.temperature!r}; must be > 0")
        if self.start not in STARTS:
            raise ValueError(f"start={self.start!r}; accepted: {STARTS}")
        if self.dtype not in DTYPES:
            raise ValueError(f"dtype={self.dtype!r}; accepted: {' | '.join(DTYPES)}")

    def with_steps(self, steps: int | None = None, step_size: float | None = None) -> "ChainSettings":
        """These settings with T and η overridden where given."""
        return dataclasses.replace(self, steps=steps or self.steps, step_size=step_size or self.step_size)


def langevin_chain(critics: CriticEnsemble, obs: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor,
                   nu, settings: ChainSettings, *, noise: torch.Tensor | None = None,
                   generator: torch.Generator | None = None) -> ChainResult:
    """Algorithm 1 at states ``obs`` with the multiplier ``nu``; ``mean``/``log_std`` are the TARGET
    actor's π_φ'(·|s).

    ``noise`` (optional, for reproducible comparisons) is (T+1, B, A): ``noise[0]`` is z₀ of the
    start, ``noise[1:]`` the step noise; otherwise all noise is drawn from ``generator``.
    """
    s = settings
    if bool((torch.as_tensor(nu) < 0).any()):
        raise ValueError(f"nu={torch.as_tensor(nu).tolist()!r}; must be ≥ 0")
    shape = mean.shape
    if noise is not None and noise.shape != (s.steps + 1, *shape):
        raise ValueError(f"noise.shape={tuple(noise.shape)}; expected {(s.steps + 1, *shape)}")
    with torch.no_grad():
        mean, log_std = mean.detach(), log_std.detach().expand_as(mean)
        z0 = noise[0] if noise is not None else torch.randn(
            shape, generator=generator, dtype=mean.dtype, device=mean.device)
        # eq. (11): start from the generator's own sample; NI: start from N(0, I).
        a0 = mean + torch.exp(log_std) * z0 if s.start == INFORMATIVE else z0
        proj = critics.project_state(obs)
        if s.fused or s.dtype != "float32":
            grad_fn = make_grad_fn(critics, proj, mean, log_std, temperature=s.temperature, nu=nu,
                                   logp_weight=s.logp_weight, compiled=s.fused, dtype=s.dtype)
        else:
            grad_fn = eager_grad_fn(critics, proj, mean, log_std, temperature=s.temperature,
                                    nu=nu, logp_weight=s.logp_weight)
        return run_chain(grad_fn, a0, steps=s.steps, step_size=s.step_size,
                         noise=None if noise is None else noise[1:], generator=generator,
                         low=s.low, high=s.high, grad_clip=s.grad_clip, grad_clip_mode=s.grad_clip_mode)


def naive_langevin_chain(critics: CriticEnsemble, actor_mean_logstd_fn, obs: torch.Tensor,
                         a0: torch.Tensor, *, steps: int, step_size: float, temperature: float,
                         nu, logp_weight: float, low, high, noise: torch.Tensor,
                         grad_clip: float | None = None, grad_clip_mode: str = "batch") -> ChainResult:
    """Reference: autograd through the full critics and a fresh actor forward at every step."""
    nr = critics.n_reward

    def energy_of(a: torch.Tensor) -> torch.Tensor:
        mean, log_std = actor_mean_logstd_fn(obs)
        q = critics(obs, a)
        logp = torch.distributions.Normal(mean, log_std.exp()).log_prob(a).sum(-1)
        q_r, q_c = reward_rows(q, nr), cost_rows(q, nr)
        return (nu * q_c.max(0).values - q_r.min(0).values) / temperature - logp_weight * logp

    def grad_fn(a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        with torch.enable_grad():
            a = a.detach().requires_grad_(True)
            energy = energy_of(a)
            (grad,) = torch.autograd.grad(energy.sum(), a)
        return energy.detach(), grad

    return run_chain(grad_fn, a0, steps=steps, step_size=step_size, noise=noise,
                     low=low, high=high, grad_clip=grad_clip, grad_clip_mode=grad_clip_mode)
