"""TRPO-Lag against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md): with the
``omnisafe`` preset (its KL averaged over the action's dimensions, ``kl_convention="mean"``, and
its conjugate gradient's ε, ``cg_eps=1e-6``) every output is OmniSafe's within 1e-5 relative: the
multiplier's step, the solve x = H⁻¹g, xᵀHx, the full step, the line search's outcome, the actor
after it, then one critic minibatch. The default's summed KL is the same step with act_dim times
less damping (trpo_lag/config.py ``kl_convention``), which the last test shows."""

import pytest

from lac_rllib.algorithms.trpo_lag.config import TRPOLagConfig
from tests.algorithms.golden import assert_matches, load
from tests.algorithms.golden_trust_region import trust_region_step

CRITICS_AND_NU = ("nu", "loss_reward_critic", "loss_cost_critic", "grad/", "after/reward_critic", "after/cost_critic")


@pytest.fixture(scope="module")
def fx():
    return load("trpo_lag-omnisafe")


def test_the_omnisafe_preset_takes_omnisafes_step(fx):
    assert_matches(trust_region_step(TRPOLagConfig, fx, preset="omnisafe"), fx.outputs)


def test_the_default_differs_in_the_actors_step_only(fx):
    got = trust_region_step(TRPOLagConfig, fx)
    assert_matches(got, fx.outputs, only=CRITICS_AND_NU)
    with pytest.raises(AssertionError, match=r"\n  x: max relative error"):
        assert_matches(got, fx.outputs, only=("x", "after/actor"))


@pytest.mark.parametrize("fields, differs", [
    ({"kl_convention": "sum"}, r"\n  x: "),  # the damping weighs half as much against the summed KL
    ({"cg_eps": 0.0}, r"\n  xHx: "),  # OmniSafe's ε in CG's denominators
    ({"kl_per_action_dim": False}, r"\n  alpha: "),  # δ on the summed KL
    ({"lagrangian_lr": 0.01}, r"\n  nu: "),
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(trust_region_step(TRPOLagConfig, fx, preset="omnisafe", **fields), fx.outputs)


def test_the_summed_kl_with_act_dim_times_the_damping_takes_the_same_step(fx):
    """[O]'s (H/d + 0.1·I) is (H + 0.1·d·I)/d: x is d times as long on the mean KL, and the step
    (√(2δ/xᵀHx)·x, δ d times smaller) and the line search are the same (CG's ε aside: 0 here)."""
    act_dim = fx.inputs["act"].shape[1]
    mean = trust_region_step(TRPOLagConfig, fx, preset="omnisafe", cg_eps=0.0)
    summed = trust_region_step(TRPOLagConfig, fx, preset="omnisafe", cg_eps=0.0, kl_convention="sum",
                               cg_damping=0.1 * act_dim)
    assert_matches(summed, mean, only=("step_direction", "acceptance_step", "after/actor"))  # 6e-7 at most
    assert_matches({"x": act_dim * summed["x"]}, {"x": mean["x"]})
