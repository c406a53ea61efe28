"""CPO against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md), three times on the
same weights and batch with Jc chosen for three of its cases: ``case2`` (c < 0, the boundary cuts
the trust region: [O]'s dual gives λ* < 0 and all 20 fractions are rejected), ``case1`` (θ_old
infeasible, a feasible part in reach: ν* > 0) and ``case0`` (recovery along −H⁻¹b). With the
``omnisafe`` preset (its KL averaged over the action's dimensions, its CG's ε, its dual:
``dual_convention="omnisafe"``) every output is OmniSafe's within 1e-5 relative: x = H⁻¹g,
p = H⁻¹b, q, r, s, A, B, the case, λ*, ν*, the full step, the line search's outcome, the actor."""

import pytest

from lac_rllib.algorithms.cpo.config import CPOConfig
from tests.algorithms.golden import assert_matches, load
from tests.algorithms.golden_trust_region import scenario_outputs, trust_region_step

SCENARIOS = ("case2", "case1", "case0")


@pytest.fixture(scope="module")
def fx():
    return load("cpo-omnisafe")


def test_the_fixture_takes_three_cases_and_both_line_search_outcomes(fx):
    out = fx.outputs
    assert [int(out[f"{s}/optim_case"]) for s in SCENARIOS] == [2, 1, 0]
    assert out["case2/lambda_star"] < 0 and out["case2/acceptance_step"] == 0  # [O]'s dual: no step
    assert out["case1/nu_star"] > 0 and out["case1/acceptance_step"] == 1


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_the_omnisafe_preset_takes_omnisafes_step(fx, scenario):
    assert_matches(trust_region_step(CPOConfig, fx, scenario, preset="omnisafe"), scenario_outputs(fx, scenario))


@pytest.mark.parametrize("scenario, fields, differs", [
    ("case2", {"dual_convention": "paper"}, r"\n  case2/lambda_star: "),  # the paper's sign of r
    ("case1", {"dual_convention": "paper"}, r"\n  case1/nu_star: "),
    ("case0", {"kl_convention": "sum"}, r"\n  case0/nu_star: "),  # half the damping: another p, s
    ("case0", {"cg_eps": 0.0}, r"\n  p: "),
])
def test_a_perturbed_learner_fails_naming_the_output(fx, scenario, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(trust_region_step(CPOConfig, fx, scenario, preset="omnisafe", **fields),
                       scenario_outputs(fx, scenario))


def test_the_recovery_does_not_read_the_dual(fx):
    got = trust_region_step(CPOConfig, fx, "case0", preset="omnisafe", dual_convention="paper")
    assert_matches(got, scenario_outputs(fx, "case0"))
