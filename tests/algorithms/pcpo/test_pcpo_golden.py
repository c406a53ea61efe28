"""PCPO against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md), Jc above the limit so
that its projection binds and its line search backs off 8 times: with the ``omnisafe`` preset (its
KL averaged over the action's dimensions, its CG's ε) and ``projection="omnisafe"`` (the default)
every output is OmniSafe's within 1e-5 relative: x = H⁻¹g, p = H⁻¹b, q, r, s, the step
√(2δ/q)·H(H⁻¹g) − ν·H⁻¹b [O pcpo.py:80, 102-109], the line search's outcome, the actor after it.
The reward half-step was η·g on the project's KL before (``trust_region.pcpo_step``): act_dim
times [O]'s on the default summed KL, and off by CG's residual on [O]'s."""

import math
from unittest import mock

import pytest

from lac_rllib.algorithms.pcpo import learner as pcpo_learner
from lac_rllib.algorithms.pcpo.config import PCPOConfig
from tests.algorithms.golden import assert_matches, load
from tests.algorithms.golden_trust_region import trust_region_step

STEP = ("step_direction", "acceptance_step", "after/actor")


@pytest.fixture(scope="module")
def fx():
    return load("pcpo-omnisafe")


def old_half_step():
    """The half-step before the fix: η·g, the KL's units not read."""
    pcpo_step = pcpo_learner.pcpo_step
    return mock.patch.object(pcpo_learner, "pcpo_step",
                             lambda *a, **k: pcpo_step(*a, **{**k, "hx": None, "kl_dims": 1}))


def test_the_projection_binds_and_the_line_search_backs_off(fx):
    out, c = fx.outputs, float(fx.inputs["ep_cost"]) - fx.meta["algo_cfgs"]["cost_limit"]
    nu = (math.sqrt(2 * fx.meta["algo_cfgs"]["target_kl"] / out["q"]) * out["r"] + c) / out["s"]  # [O pcpo.py:105]
    assert nu > 1 and out["acceptance_step"] == 9


def test_the_omnisafe_preset_takes_omnisafes_step(fx):
    assert_matches(trust_region_step(PCPOConfig, fx, preset="omnisafe"), fx.outputs)


@pytest.mark.parametrize("fields, differs", [
    ({"projection": "kl"}, r"\n  step_direction: "),  # the paper's eq. 7
    ({"kl_convention": "sum"}, r"\n  x: "),
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(trust_region_step(PCPOConfig, fx, preset="omnisafe", **fields), fx.outputs)


def test_the_old_half_step_fails_naming_the_step(fx):
    with old_half_step(), pytest.raises(AssertionError, match=r"\n  step_direction: "):
        assert_matches(trust_region_step(PCPOConfig, fx, preset="omnisafe"), fx.outputs)


def test_the_omnisafe_step_does_not_depend_on_the_kls_convention(fx):
    """On the summed KL with act_dim times the damping (the same H, CG's ε 0 on both) the step is
    the one [O]'s mean KL gives; the old half-step η·g was act_dim times longer there."""
    act_dim = fx.inputs["act"].shape[1]
    summed = {"kl_convention": "sum", "cg_damping": 0.1 * act_dim, "cg_eps": 0.0}
    mean = trust_region_step(PCPOConfig, fx, preset="omnisafe", cg_eps=0.0)
    assert_matches(trust_region_step(PCPOConfig, fx, preset="omnisafe", **summed), mean, only=STEP)
    with old_half_step(), pytest.raises(AssertionError, match=r"\n  step_direction: "):
        assert_matches(trust_region_step(PCPOConfig, fx, preset="omnisafe", **summed), mean, only=STEP)
