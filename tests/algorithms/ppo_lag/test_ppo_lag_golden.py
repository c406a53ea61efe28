"""PPO-Lag's update is OmniSafe 0.5.0's: the multiplier's Adam step, both critics' minibatch steps
(MSE + critic L2, clip, Adam) and the actor's (the clipped surrogate on (A^R − λ·A^C)/(1 + λ), clip,
Adam) on the recorded batch and weights, every output within 1e-5 relative
(tests/fixtures/golden/README.md); a learner with another clip range or multiplier rate does not."""

import pytest

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from tests.algorithms.golden import assert_matches, load, on_policy_step


@pytest.fixture(scope="module")
def fx():
    return load("ppo_lag-omnisafe")


def test_the_safety_gym_preset_takes_omnisafes_step(fx):
    assert_matches(on_policy_step(PPOLagConfig, fx), fx.outputs)


@pytest.mark.parametrize("fields, differs", [
    ({"clip_param": 0.1}, "grad/actor.mean"),  # the surrogate's clip range
    ({"lagrangian_lr": 0.01}, "nu"),  # the multiplier's rate
    ({"critic_l2": 0.0}, "grad/reward_critic"),  # OmniSafe's use_critic_norm
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(on_policy_step(PPOLagConfig, fx, **fields), fx.outputs)
