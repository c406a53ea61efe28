"""The trust-region step that TRPO-Lagrangian, CPO and PCPO share: flat parameters, the
Fisher-vector product, conjugate gradient, a backtracking line search with a pluggable acceptance
test, and CPO's and PCPO's closed-form steps as pure functions.

Sources: [TRPO] Schulman et al. 2015 (App. C); [CPO] Achiam et al. 2017 (§6.1, the approximate
problem and its dual; §6.2, infeasible recovery; App. 10.2, the closed form); [PCPO] Yang et al.
2020 (eq. 7); [O] OmniSafe (``omnisafe/``, lines at commit 15603dd): ``utils/math.py``,
``utils/tools.py``, ``algorithms/on_policy/base/natural_pg.py``, ``base/trpo.py``,
``second_order/cpo.py``, ``second_order/pcpo.py``; [S] safety-starter-agents
``safe_rl/pg/trust_region.py``, ``safe_rl/pg/agents.py``.

Conventions, as in [CPO §6.1]: a step Δθ moves θ_old to θ_old + Δθ; g is the gradient of the
reward surrogate (the ascent direction, minus the gradient of the loss), b that of the cost
surrogate, c = J_C − d the cost gap (scaled as the caller wants: [S] divides it by the mean episode
length, [O] does not), δ the KL radius, and the trust region is ½ΔθᵀHΔθ ≤ δ with H the Hessian of
the mean KL. Plain torch, no RLlib.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

EPS = 1e-8  # [S utils.py EPS]; [O] uses 1e-8 in the steps and 1e-6 inside its CG


def flat_params(params: Sequence[Tensor]) -> Tensor:
    """The parameters as one detached vector (a copy) [O tools.py:35-65]."""
    return torch.cat([p.detach().reshape(-1) for p in params])


def set_flat_params_(params: Sequence[Tensor], flat: Tensor) -> None:
    """Copy ``flat`` into the parameters in place. A copy, not an assignment of views (as
    [O tools.py:94-129] does), so the values are bit for bit those of ``flat`` and the parameters
    never alias it."""
    if (n := sum(p.numel() for p in params)) != flat.numel():
        raise ValueError(f"{flat.numel()} values for {n} parameters")
    offset = 0
    with torch.no_grad():
        for p in params:
            p.copy_(flat[offset:offset + p.numel()].view_as(p))
            offset += p.numel()


def flat_grad(output: Tensor, params: Sequence[Tensor], **autograd_kwargs) -> Tensor:
    """∂output/∂params as one vector, zeros for a parameter ``output`` does not depend on."""
    params = list(params)
    autograd_kwargs.setdefault("allow_unused", True)
    grads = torch.autograd.grad(output, params, **autograd_kwargs)
    return torch.cat([(torch.zeros_like(p) if g is None else g).reshape(-1) for p, g in zip(params, grads)])


def masked_mean(x: Tensor, mask: Tensor | None) -> Tensor:
    """Mean of ``x`` over the real rows (``mask`` True; trailing dimensions averaged too).

    Phantom rows (RLlib's zero padding, ``LOSS_MASK`` False) must change neither the surrogate nor
    the Fisher-vector product: reduce both with this. ``torch.where`` rather than a product, so a
    non-finite value in a phantom row cannot leak into the mean."""
    if mask is None:
        return x.mean()
    m = mask.to(torch.bool).reshape(mask.shape + (1,) * (x.dim() - mask.dim())).expand_as(x)
    return torch.where(m, x, torch.zeros_like(x)).sum() / m.sum().clamp_min(1)


def fisher_vector_product(mean_kl_fn: Callable[[], Tensor], params: Sequence[Tensor],
                          damping: float = 0.1) -> Callable[[Tensor], Tensor]:
    """v ↦ (∇²KL̄) v + damping·v at the current parameters [TRPO App. C.1; O natural_pg.py:74-119].

    ``mean_kl_fn()`` returns the mean over the real rows of KL(π_old ‖ π_θ), π_old's distribution
    inputs detached: its value and gradient are 0 at θ_old, its Hessian is the Fisher matrix. The
    product is the double backward ∇_θ((∇_θ KL̄)·v). The first-order graph is built once here and
    kept, so each product costs one backward pass ([O] redoes the forward pass per product); the
    closure is valid only while the parameters are unchanged. KL(π_θ ‖ π_old), [S network.py:107]'s
    direction, has the same Hessian at θ_old. RLlib's ``TorchDiagGaussian.kl`` and [S] sum over
    action dimensions, [O]'s ``Normal`` KL averages over them (δ_O = δ/act_dim)."""
    params = list(params)
    grad_kl = flat_grad(mean_kl_fn(), params, create_graph=True)

    def fvp(v: Tensor) -> Tensor:
        if not grad_kl.requires_grad:  # KL̄ is linear in θ: its Hessian is 0
            return damping * v
        return flat_grad(grad_kl @ v.detach(), params, retain_graph=True) + damping * v

    return fvp


def conjugate_gradient(Avp: Callable[[Tensor], Tensor], b: Tensor, iters: int = 10,
                       residual_tol: float = 1e-10, eps: float = 0.0) -> Tensor:
    """x ≈ A⁻¹b for a symmetric positive-definite A known by its products [TRPO App. C;
    O math.py:86-132; S trust_region.py:33-46]: at most ``iters`` products, stopping once ‖r‖ <
    ``residual_tol`` [O math.py:127]. x₀ = 0, so r₀ = b without a product ([O] spends one on A·0),
    and b = 0 returns 0 without one. ``eps`` is added to both denominators as [O] does (1e-6; [S]
    1e-8 in α only); it biases the step once ‖r‖² nears it, so the default, Schulman's, is 0."""
    x, r = torch.zeros_like(b), b.clone()
    p, rdotr = r.clone(), r @ r
    for _ in range(iters):
        if rdotr.sqrt() < residual_tol:
            break
        z = Avp(p)
        alpha = rdotr / (p @ z + eps)
        x += alpha * p
        r -= alpha * z
        new_rdotr = r @ r
        p = r + (new_rdotr / (rdotr + eps)) * p
        rdotr = new_rdotr
    return x


def trpo_step(hinv_g: Tensor, q: float | Tensor, max_kl: float) -> Tensor:
    """The natural-gradient step scaled onto the trust region's boundary, √(2δ/q)·H⁻¹g with
    q = gᵀH⁻¹g ([TRPO App. C]; [O trpo.py:190-193] passes q = xᵀHx)."""
    return math.sqrt(2 * max_kl / (float(q) + EPS)) * hinv_g


@dataclass(frozen=True)
class LineSearchResult:
    """``fraction`` of the full step kept (0 when none was accepted); ``backtracks``: the fractions
    rejected before it ([S]'s ``BacktrackIters``; [O]'s ``AcceptanceStep`` is backtracks + 1 when
    accepted, else 0)."""

    accepted: bool
    fraction: float
    backtracks: int


def line_search(params: Sequence[Tensor], step: Tensor, accept: Callable[[float], bool], *,
                backtracks: int = 10, decay: float = 0.8) -> LineSearchResult:
    """Backtracking line search over θ_old + decay^j·step, j = 0 … backtracks−1 [TRPO App. C;
    S agents.py:187-202; O trpo.py:56-148].

    ``accept(fraction)`` runs (without autograd) with the parameters SET to θ_old + fraction·step,
    so it evaluates the new surrogate and KL with the model itself; the first accepted point stays.
    If none is, θ_old is restored bit for bit. [O] 15 backtracks for TRPO (trpo.py:66), 20 for CPO
    (cpo.py:430), 200 for PCPO (pcpo.py:122); [S] 10; decay 0.8 in both."""
    params = list(params)
    theta_old = flat_params(params)
    with torch.no_grad():
        for j in range(backtracks):
            fraction = decay**j
            set_flat_params_(params, theta_old + fraction * step)
            if accept(fraction):
                return LineSearchResult(True, fraction, j)
        set_flat_params_(params, theta_old)
    return LineSearchResult(False, 0.0, backtracks)


def _finite_values(*fns: Callable[[], Tensor | float]) -> list[float] | None:
    """The values of ``fns``, or None if one is not finite or the distribution could not be built
    (torch raises ValueError on non-finite parameters; [O cpo.py:123-128] rejects that step)."""
    try:
        values = [float(v.detach()) if isinstance(v := fn(), Tensor) else float(v) for fn in fns]
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def trpo_acceptance(loss_fn: Callable[[], Tensor], kl_fn: Callable[[], Tensor], loss_old: float,
                    max_kl: float) -> Callable[[float], bool]:
    """TRPO's test: the loss (the negated surrogate) does not get worse, loss ≤ loss_old, and
    KL̄ ≤ δ [O trpo.py:116-128: rejects loss_improve < 0 and kl > target_kl; S agents.py:194].
    Non-finite values are rejected ([O] checks only the loss, so a NaN KL passes there)."""
    def accept(fraction: float) -> bool:
        values = _finite_values(loss_fn, kl_fn)
        return values is not None and values[0] <= loss_old and values[1] <= max_kl

    return accept


def cpo_acceptance(loss_fn: Callable[[], Tensor], cost_fn: Callable[[], Tensor], kl_fn: Callable[[], Tensor],
                   loss_old: float, cost_old: float, c: float, max_kl: float, case: int) -> Callable[[float], bool]:
    """CPO's test [O cpo.py:135-165; S agents.py:339-341]: the loss may not rise in cases 2-4 only
    (recovery, cases 0-1, may trade reward for cost); the cost surrogate may rise by at most
    max(−c, 0); KL̄ ≤ δ. PCPO uses it with case 0 [O pcpo.py:111-124 leaves optim_case at 0]."""
    def accept(fraction: float) -> bool:
        values = _finite_values(loss_fn, cost_fn, kl_fn)
        if values is None:
            return False
        loss, cost, kl = values
        return (case <= 1 or loss <= loss_old) and cost - cost_old <= max(-c, 0.0) and kl <= max_kl

    return accept


@dataclass(frozen=True)
class CPOStep:
    """The case (0-4, [O cpo.py:215-268]), the dual (λ*, ν*), the step Δθ, and the scalars
    q = gᵀH⁻¹g, r = gᵀH⁻¹b, s = bᵀH⁻¹b, A = q − r²/s, B = 2δ − c²/s that [O] logs."""

    case: int
    lam: float
    nu: float
    step_direction: Tensor
    q: float
    r: float
    s: float
    A: float
    B: float


def cpo_step(g: Tensor, b: Tensor, hinv_g: Tensor, hinv_b: Tensor, c: float, max_kl: float, *,
             q: float | None = None, grad_tol: float = 1e-6, convention: str = "paper") -> CPOStep:
    """The solution of [CPO §6.1], max_Δ gᵀΔ s.t. bᵀΔ + c ≤ 0, ½ΔᵀHΔ ≤ δ, from its dual.

    Cases, numbered and tested as [O cpo.py:237-266] ([S agents.py:270-299], bᵀb ≤ 1e-8 there):
    4: bᵀb ≤ grad_tol and c < 0, no usable constraint; 3: c < 0, B < 0, the whole trust region is
    feasible; 2: c < 0 ≤ B, the boundary cuts it; 1: c ≥ 0, B ≥ 0, θ_old infeasible, a feasible
    part exists; 0: c ≥ 0, B < 0, none exists. Steps: cases 3-4 the TRPO step (λ* = √(q/2δ),
    ν* = 0); cases 1-2 Δ = (H⁻¹g − ν*H⁻¹b)/λ* [CPO §6.1] with (λ*, ν*) in closed form
    [CPO App. 10.2]; case 0 the recovery step Δ = −√(2δ/s)·H⁻¹b [CPO §6.2; O cpo.py:330-335].
    ``q`` defaults to gᵀH⁻¹g ([O] passes xᵀHx). ``convention="omnisafe"`` reproduces [O]'s dual,
    which has the sign of r flipped (see :func:`_cpo_dual`)."""
    q = float(g @ hinv_g) if q is None else float(q)
    r, s = float(g @ hinv_b), float(b @ hinv_b)  # [O cpo.py:394-396]
    if float(b @ b) <= grad_tol and c < 0:
        case, A, B = 4, 0.0, 0.0
    else:
        A, B = q - r**2 / (s + EPS), 2 * max_kl - c**2 / (s + EPS)  # [O cpo.py:246-247]
        if c < 0:
            case = 3 if B < 0 else 2
        else:
            case = 1 if B >= 0 else 0
    if case in (3, 4):
        lam, nu, step = math.sqrt(q / (2 * max_kl)), 0.0, trpo_step(hinv_g, q, max_kl)  # [O cpo.py:284-289]
    elif case in (1, 2):
        lam, nu = _cpo_dual(q, r, s, c, A, B, max_kl, convention)
        step = (hinv_g - nu * hinv_b) / (lam + EPS)  # [CPO §6.1; O cpo.py:328]
    else:
        lam, nu = 0.0, math.sqrt(2 * max_kl / (s + EPS))
        step = -nu * hinv_b
    return CPOStep(case, lam, nu, step, q, r, s, A, B)


def _cpo_dual(q: float, r: float, s: float, c: float, A: float, B: float, max_kl: float,
              convention: str) -> tuple[float, float]:
    """(λ*, ν*) of cases 1-2 [CPO App. 10.2; S agents.py:304-313; O cpo.py:291-326].

    App. 10.2 writes the problem as min gᵀx, so its r is −gᵀH⁻¹b in our ascent terms ([S]'s g is
    the gradient of the loss, so its r is that): ν*(λ) = (λc − r_d)/s with r_d = −r, and
    λ* = argmax of f_a(λ) = −½(A/λ + Bλ) − r_d·c/s on the λ where ν* > 0, f_b(λ) = −½(q/λ + 2δλ)
    where ν* = 0, each maximiser √(A/B), √(q/2δ) projected onto its interval (split at r_d/c).
    [O] plugs its ascent-form r straight into these formulas (r_d = +r), and projects with
    ``torch.clamp``, whose upper bound wins on an empty interval: ``convention="omnisafe"``."""
    omnisafe = convention == "omnisafe"
    if convention not in ("paper", "omnisafe"):
        raise ValueError(f"convention must be 'paper' or 'omnisafe', not {convention!r}")
    r_d = r if omnisafe else -r
    split = r_d / (c + EPS) if omnisafe else r_d / (c if c != 0 else EPS)  # [O cpo.py:307: c + 1e-8]

    def project(x: float, low: float, high: float) -> float:
        return min(max(x, low), high) if omnisafe else max(low, min(x, high))

    interval_a, interval_b = ((0.0, split), (split, math.inf)) if c < 0 else ((split, math.inf), (0.0, split))
    lam_a = project(math.sqrt(max(A, 0.0) / max(B, EPS)), *interval_a)
    lam_b = project(math.sqrt(q / (2 * max_kl)), *interval_b)
    f_a = -0.5 * (A / (lam_a + EPS) + B * lam_a) - r_d * c / (s + EPS)
    f_b = -0.5 * (q / (lam_b + EPS) + 2 * max_kl * lam_b)
    lam = lam_a if f_a >= f_b else lam_b
    return lam, max(0.0, lam * c - r_d) / (s + EPS)


@dataclass(frozen=True)
class PCPOStep:
    """The step Δθ, the projection's coefficient ν (0 when the reward step is feasible), and
    q = gᵀH⁻¹g, r = gᵀH⁻¹b, s = bᵀH⁻¹b."""

    step_direction: Tensor
    nu: float
    q: float
    r: float
    s: float


def pcpo_step(g: Tensor, b: Tensor, hinv_g: Tensor, hinv_b: Tensor, c: float, max_kl: float, *,
              metric: str = "kl", q: float | None = None, hx: Tensor | None = None, kl_dims: int = 1) -> PCPOStep:
    """PCPO's reward step then projection onto the cost half-space {Δ: bᵀΔ + c ≤ 0} [PCPO eq. 7]:

        Δ = η·H⁻¹g − max(0, (η·bᵀH⁻¹g + c) / bᵀL⁻¹b)·L⁻¹b,   η = √(2δ/gᵀH⁻¹g).

    ``metric="kl"``: L = H, the KL projection; ``"l2"``: L = I, the Euclidean one. ``"omnisafe"``:
    [O pcpo.py:80, 102-109], whose reward step is η·H(H⁻¹g) (``hx``, the damped product of the
    solve; g, which it equals to CG's residual, if not given) while the projection's coefficient is
    the KL one, computed for η·H⁻¹g; so its step does not land on the boundary unless H ∝ I. [O]'s
    KL is the mean over the action's dimensions: on a KL summed over ``kl_dims`` of them, δ is
    kl_dims times [O]'s and q = xᵀHx 1/kl_dims (H·x is the same), so η is kl_dims times [O]'s
    and its reward step is η·Hx/kl_dims; the projection's term does not depend on the units. Its
    line search is CPO's, case 0."""
    if metric not in ("kl", "l2", "omnisafe"):
        raise ValueError(f"metric must be 'kl', 'l2' or 'omnisafe', not {metric!r}")
    q = float(g @ hinv_g) if q is None else float(q)
    r, s = float(g @ hinv_b), float(b @ hinv_b)
    eta = math.sqrt(2 * max_kl / (q + EPS))
    half = eta * (((g if hx is None else hx) / kl_dims) if metric == "omnisafe" else hinv_g)
    direction, norm = (b, float(b @ b)) if metric == "l2" else (hinv_b, s)
    nu = max(0.0, (eta * r + c) / (norm + EPS))  # η·r = bᵀ(η·H⁻¹g), the reward step's cost change
    return PCPOStep(half - nu * direction, nu, q, r, s)
