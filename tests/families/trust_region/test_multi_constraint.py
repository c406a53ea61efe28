"""CPO's and PCPO's steps with several constraints against cases solved by hand (H = I, so
H⁻¹v = v and the trust region ½ΔᵀΔ ≤ δ = ½ is the unit ball), and against the one-constraint
steps they must reduce to."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lac_rllib.families.trust_region.multi_constraint import cpo_step_several, nonneg_qp, pcpo_step_several
from lac_rllib.families.trust_region.step import cpo_step, pcpo_step

R2 = math.sqrt(2.0)


def t(*v):
    return torch.tensor(v, dtype=torch.float64)


def cpo(g, rows, c, max_kl=0.5):
    B = torch.stack(rows)
    return cpo_step_several(g, B, g, B, c, max_kl)  # H = I: H⁻¹g = g, H⁻¹B = B


def test_one_active_the_other_slack():
    # max Δ1 in the unit disc with Δ1 + Δ2 ≤ 1/√2 (binds) and Δ2 ≤ 0.9 (slack): Δ = (cos 15°, −sin 15°).
    out = cpo(t(1.0, 0.0), [t(1.0, 1.0) / R2, t(0.0, 1.0)], [-0.5, -0.9])
    assert out.case == "active"
    expected = (math.cos(math.radians(15)), -math.sin(math.radians(15)))
    assert out.step_direction.tolist() == pytest.approx(expected, abs=1e-6)
    assert out.nu[0] > 0.1 and out.nu[1] == pytest.approx(0.0, abs=1e-8)


def test_both_active():
    # max Δ1 + ½Δ3 in the unit ball with Δ1 + Δ2 ≤ ½ and Δ1 − Δ2 ≤ ½: the vertex line Δ1 = ½, Δ2 = 0,
    # Δ3 = √(1 − ¼); KKT by hand: λ = ½/Δ3, ν1 = ν2 = (1 − λ/2)/√2.
    c = -0.5 / R2
    out = cpo(t(1.0, 0.0, 0.5), [t(1.0, 1.0, 0.0) / R2, t(1.0, -1.0, 0.0) / R2], [c, c])
    assert out.case == "active"
    d3 = math.sqrt(0.75)
    assert out.step_direction.tolist() == pytest.approx((0.5, 0.0, d3), abs=1e-6)
    lam = 0.5 / d3
    assert out.lam == pytest.approx(lam, rel=1e-5)
    assert out.nu == pytest.approx(((1 - lam / 2) * R2 / 2,) * 2, rel=1e-5)


def test_inactive_takes_the_trpo_step():
    out = cpo(t(1.0, 0.0), [t(1.0, 0.0), t(0.0, 1.0)], [-2.0, -2.0])
    assert out.case == "inactive" and out.nu == (0.0, 0.0)
    assert out.step_direction.tolist() == pytest.approx((1.0, 0.0))


@pytest.mark.parametrize("c", [(2.0, 2.0), (2.0, 1.0)])
def test_infeasible_recovery_walks_to_the_nearest_feasible_point(c):
    # Δ1 ≤ −c1 and Δ2 ≤ −c2 lie outside the unit disc: the nearest point of their intersection is
    # −c, so the step is −c/|c| (the trust region's edge towards it).
    out = cpo(t(1.0, 0.0), [t(1.0, 0.0), t(0.0, 1.0)], list(c))
    assert out.case == "recovery"
    norm = math.hypot(*c)
    assert out.step_direction.tolist() == pytest.approx((-c[0] / norm, -c[1] / norm), abs=1e-9)


def test_no_episode_yet_never_binds():
    out = cpo(t(1.0, 0.0), [t(1.0, 0.0), t(0.0, 1.0)], [-math.inf, -math.inf])
    assert out.case == "inactive"


@pytest.mark.parametrize("c", [-0.9, -0.2, 0.3, 2.0])
def test_one_constraint_is_cpo_s_own_step(c):
    # The several-constraint maths with K = 1 lands where the closed-form dual does, in each case
    # (a random H keeps the problem non-degenerate).
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(4, 4, generator=gen, dtype=torch.float64)
    H = a @ a.T + 4 * torch.eye(4, dtype=torch.float64)
    g, b = torch.randn(4, generator=gen, dtype=torch.float64), torch.randn(4, generator=gen, dtype=torch.float64)
    hinv_g, hinv_b = torch.linalg.solve(H, g), torch.linalg.solve(H, b)
    one = cpo_step(g, b, hinv_g, hinv_b, c, 0.05)
    several = cpo_step_several(g, b[None], hinv_g, hinv_b[None], [c], 0.05)
    assert several.step_direction.tolist() == pytest.approx(one.step_direction.tolist(), rel=1e-5, abs=1e-8)


def test_pcpo_projects_onto_the_intersection():
    # (1, 0) onto {Δ1 + Δ2 ≤ ½} ∩ {Δ2 ≥ −0.1}: the first alone gives (0.75, −0.25), which breaks
    # the second, so both bind: the vertex (0.6, −0.1), ν = (0.4·√2, 0.3).
    B = torch.stack([t(1.0, 1.0) / R2, t(0.0, -1.0)])
    g = t(1.0, 0.0)
    out = pcpo_step_several(g, B, g, B, [-0.5 / R2, -0.1], 0.5)
    assert out.step_direction.tolist() == pytest.approx((0.6, -0.1), abs=1e-9)
    assert out.nu == pytest.approx((0.4 * R2, 0.3), abs=1e-7)  # η = √(2δ/(q + 1e-8))


def test_pcpo_one_constraint_is_pcpo_s_own_step():
    gen = torch.Generator().manual_seed(1)
    a = torch.randn(4, 4, generator=gen, dtype=torch.float64)
    H = a @ a.T + 4 * torch.eye(4, dtype=torch.float64)
    g, b = torch.randn(4, generator=gen, dtype=torch.float64), torch.randn(4, generator=gen, dtype=torch.float64)
    hinv_g, hinv_b = torch.linalg.solve(H, g), torch.linalg.solve(H, b)
    for c in (-0.5, 0.4):
        one = pcpo_step(g, b, hinv_g, hinv_b, c, 0.05)
        several = pcpo_step_several(g, b[None], hinv_g, hinv_b[None], [c], 0.05)
        assert several.step_direction.tolist() == pytest.approx(one.step_direction.tolist(), rel=1e-9, abs=1e-12)


def test_nonneg_qp_checks_kkt():
    S = np.array([[2.0, 0.5], [0.5, 1.0]])
    d = np.array([1.0, -3.0])
    nu, value = nonneg_qp(S, d)
    assert nu.tolist() == pytest.approx([0.5, 0.0]) and value == pytest.approx(0.25)
