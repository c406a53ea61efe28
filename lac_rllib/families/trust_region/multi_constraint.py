"""CPO's and PCPO's steps with K constraints (plain torch and numpy; step.py has the one-constraint
steps, which runs with one constraint still take, bit for bit).

The linearised problem of CPO with K constraints [CPO §6.1, which states it for several]:

    max_Δ gᵀΔ   s.t.   c_k + b_kᵀΔ ≤ 0 (k = 1..K),   ½ΔᵀHΔ ≤ δ,

with B the K×n matrix of the b_k. Its dual: with Q(ν) = q − 2rᵀν + νᵀSν (q = gᵀH⁻¹g,
r = BH⁻¹g, S = BH⁻¹Bᵀ), stationarity gives Δ = H⁻¹(g − Bᵀν)/λ and λ = √(Q(ν)/2δ), so

    ν* = argmin_{ν ≥ 0}  √(2δ·Q(ν)) − νᵀc,                                   (convex)

solved numerically (scipy's L-BFGS-B, bounds ν ≥ 0, its gradient in closed form); one variable
per constraint, as the CPO paper's dual has. Three cases:

- "inactive": TRPO's step √(2δ/q)·H⁻¹g already meets every linearised constraint: it is the
  optimum (ν* = 0);
- "active": the dual's (λ*, ν*), some ν*_k > 0: the constraints the step lies on;
- "recovery": no Δ in the trust region meets them all: the closest point of their intersection in
  H's metric, Δ_f = −H⁻¹Bᵀν_f with ν_f = argmax_{ν ≥ 0} νᵀc − ½νᵀSν (its squared H-norm is 2·that
  maximum, which exceeds 2δ exactly when the problem is infeasible), scaled onto the trust region:
  Δ = √(2δ / ν_fᵀSν_f)·Δ_f. With one constraint ν_f = c/s and this is CPO's recovery −√(2δ/s)·H⁻¹b
  [CPO §6.2]; with several it walks towards every violated constraint at once, weighted by how far
  each is.

PCPO's projection of the reward step Δ₀ onto the intersection of the K half-spaces in the metric L
(H or I) [PCPO eq. 7, onto a polyhedron]: Δ = Δ₀ − L⁻¹Bᵀν with ν = argmax_{ν ≥ 0} νᵀ(BΔ₀ + c) −
½νᵀ(BL⁻¹Bᵀ)ν, a K-variable quadratic programme solved exactly by its active set (:func:`nonneg_qp`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import minimize
from torch import Tensor

from lac_rllib.families.trust_region.step import EPS, _finite_values

#: The one-constraint steps' case numbers (step.py, CPO's ``cpo_case``) of each case here: the
#: recovery 0, the dual's step 2, TRPO's step 3.
CASE_NUMBERS = {"recovery": 0, "active": 2, "inactive": 3}
#: A constraint's cost slack after the TRPO step within which it counts as met (float rounding).
TOLERANCE = 1e-10


def nonneg_qp(S: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, float]:
    """argmax_{ν ≥ 0} νᵀd − ½νᵀSν (S positive semi-definite, K small) and its maximum, exactly:
    every active set A (ν_A = S_AA⁻¹d_A, the rest 0) is tried and the best one meeting the KKT
    conditions (ν_A ≥ 0, d − Sν ≤ 0 off A) kept; 2^K small linear solves."""
    k = len(d)
    best, best_value = np.zeros(k), 0.0
    for size in range(1, k + 1):
        for active in itertools.combinations(range(k), size):
            idx = list(active)
            try:
                sub = np.linalg.solve(S[np.ix_(idx, idx)], d[idx])
            except np.linalg.LinAlgError:
                continue
            if (sub < -TOLERANCE).any():
                continue
            nu = np.zeros(k)
            nu[idx] = np.maximum(sub, 0.0)
            slack = d - S @ nu
            if np.delete(slack, idx).max(initial=-np.inf) > 1e-9 * (1 + np.abs(d).max()):
                continue
            value = float(nu @ d - 0.5 * nu @ S @ nu)
            if value > best_value:
                best, best_value = nu, value
    return best, best_value


@dataclass(frozen=True)
class SeveralCPOStep:
    """The case ("inactive", "active", "recovery"), the dual (λ*, ν* one per constraint), the step,
    and q, r, S."""

    case: str
    lam: float
    nu: tuple[float, ...]
    step_direction: Tensor
    q: float
    r: np.ndarray
    S: np.ndarray


def cpo_step_several(g: Tensor, B: Tensor, hinv_g: Tensor, hinv_B: Tensor, c, max_kl: float, *,
                     q: float | None = None) -> SeveralCPOStep:
    """The solution of the K-constraint linearised problem (the module docstring). ``B`` and
    ``hinv_B`` are (K, n): each constraint's b_k and H⁻¹b_k; ``c`` its K gaps Ĵ_Ck − b_k (−∞: no
    episode completed yet, never violated)."""
    c = np.asarray(c, dtype=np.float64)
    q = float(g @ hinv_g) if q is None else float(q)
    r = (B.double() @ hinv_g.double()).numpy()
    S = (B.double() @ hinv_B.double().T).numpy()
    S = 0.5 * (S + S.T)
    trpo = math.sqrt(2 * max_kl / (q + EPS))
    known = np.isfinite(c)
    if not known.any() or (c[known] + trpo * r[known] <= TOLERANCE).all():  # bᵀ(√(2δ/q)·H⁻¹g) = √(2δ/q)·r
        return SeveralCPOStep("inactive", math.sqrt(q / (2 * max_kl)), (0.0,) * len(c), trpo * hinv_g, q, r, S)
    cc = np.where(known, c, -1e12)  # a constraint with no episode yet never binds
    nu_f, p_star = nonneg_qp(S, cc)
    if p_star > max_kl:  # min ½ΔᵀHΔ over the linearised feasible set exceeds δ: infeasible
        scale = math.sqrt(2 * max_kl / (float(nu_f @ S @ nu_f) + EPS))
        step = -scale * (torch.from_numpy(nu_f).to(hinv_B.dtype) @ hinv_B)
        return SeveralCPOStep("recovery", 0.0, tuple(scale * nu_f), step, q, r, S)
    nu = _dual(q, r, S, cc, max_kl)
    Q = max(q - 2 * r @ nu + nu @ S @ nu, EPS)
    lam = math.sqrt(Q / (2 * max_kl))
    step = (hinv_g - torch.from_numpy(nu).to(hinv_B.dtype) @ hinv_B) / (lam + EPS)
    return SeveralCPOStep("active", lam, tuple(float(v) for v in nu), step, q, r, S)


def _dual(q: float, r: np.ndarray, S: np.ndarray, c: np.ndarray, max_kl: float) -> np.ndarray:
    """ν* = argmin_{ν ≥ 0} √(2δ·Q(ν)) − νᵀc, Q(ν) = q − 2rᵀν + νᵀSν."""
    def objective(nu):
        Q = max(q - 2 * r @ nu + nu @ S @ nu, EPS)
        root = math.sqrt(2 * max_kl * Q)
        return root - nu @ c, max_kl * (2 * S @ nu - 2 * r) / root - c

    k = len(c)
    starts = [np.zeros(k), np.maximum(nonneg_qp(S, c)[0], 0.0) + 1e-3]
    best = None
    for x0 in starts:
        out = minimize(objective, x0, jac=True, method="L-BFGS-B", bounds=[(0.0, None)] * k,
                       options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 1000})
        if best is None or out.fun < best.fun:
            best = out
    return np.maximum(best.x, 0.0)


@dataclass(frozen=True)
class SeveralPCPOStep:
    """The step, and the projection's coefficients ν (one per constraint, 0 where the reward step
    meets it)."""

    step_direction: Tensor
    nu: tuple[float, ...]


def pcpo_step_several(g: Tensor, B: Tensor, hinv_g: Tensor, hinv_B: Tensor, c, max_kl: float, *,
                      metric: str = "kl", q: float | None = None) -> SeveralPCPOStep:
    """PCPO's reward step η·H⁻¹g, η = √(2δ/gᵀH⁻¹g), projected onto the intersection of the K
    half-spaces {Δ: c_k + b_kᵀΔ ≤ 0} in the metric L = H (``"kl"``) or I (``"l2"``); ``c`` as in
    :func:`cpo_step_several`. (OmniSafe's own variant is a one-constraint step: step.py.)"""
    if metric not in ("kl", "l2"):
        raise ValueError(f"metric must be 'kl' or 'l2' with several constraints, not {metric!r}")
    c = np.asarray(c, dtype=np.float64)
    q = float(g @ hinv_g) if q is None else float(q)
    eta = math.sqrt(2 * max_kl / (q + EPS))
    half = eta * hinv_g
    directions = hinv_B if metric == "kl" else B  # L⁻¹b_k
    M = (B.double() @ directions.double().T).numpy()
    M = 0.5 * (M + M.T)
    d = (B.double() @ half.double()).numpy() + np.where(np.isfinite(c), c, -1e12)
    nu, _ = nonneg_qp(M, d)
    return SeveralPCPOStep(half - torch.from_numpy(nu).to(directions.dtype) @ directions, tuple(float(v) for v in nu))


def several_acceptance(loss_fn, cost_fns, kl_fn, loss_old: float, costs_old, c, max_kl: float, *,
                       loss_may_rise: bool):
    """CPO's line-search test (step.py ``cpo_acceptance``) with K constraints: each cost surrogate may
    rise by at most max(−c_k, 0), KL̄ ≤ δ, and the reward's loss may not rise unless
    ``loss_may_rise`` (a recovery step; PCPO's, always, as its one-constraint search)."""
    def accept(fraction: float) -> bool:
        values = _finite_values(loss_fn, kl_fn, *cost_fns)
        if values is None:
            return False
        loss, kl, *costs = values
        return ((loss_may_rise or loss <= loss_old) and kl <= max_kl
                and all(new - old <= max(-gap, 0.0) for new, old, gap in zip(costs, costs_old, c)))

    return accept
