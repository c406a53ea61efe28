"""P3O against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md): both critics and the
actor's PPO-clipped loss on A^R plus κ·ReLU(mean(r·A^C) + Ĵ_C − b), one clip and Adam step, every
output within 1e-5 relative. The project logs the policy's whole loss; OmniSafe logs its two
terms (Loss_pi, Loss_pi_cost): their sum is compared."""

import pytest

from lac_rllib.algorithms.p3o.config import P3OConfig
from tests.algorithms.golden import assert_matches, load, on_policy_step


@pytest.fixture(scope="module")
def fx():
    fx = load("p3o-omnisafe")
    out = dict(fx.outputs)
    out["loss_pi"] = out["loss_pi"] + out.pop("loss_pi_cost")
    fx.outputs = out
    return fx


def test_the_safety_gym_preset_takes_omnisafes_step(fx):
    assert fx.outputs["loss_pi"] > 1.0  # the penalty is active in this batch (Ĵ_C − b = 15)
    got = on_policy_step(P3OConfig, fx)
    got.pop("nu")  # the project reports κ·1[penalty] there; P3O has no multiplier
    assert_matches(got, fx.outputs)


@pytest.mark.parametrize("fields, differs", [({"kappa": 10.0}, "loss_pi"), ({"cost_limit": 45.0}, "loss_pi")])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(on_policy_step(P3OConfig, fx, **fields), fx.outputs)
