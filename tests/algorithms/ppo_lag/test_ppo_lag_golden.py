"""PPO-Lag's update is OmniSafe 0.5.0's: the multiplier's Adam step, both critics' minibatch steps
(MSE + critic L2, clip, Adam) and the actor's (the clipped surrogate on (A^R − λ·A^C)/(1 + λ), clip,
Adam) on the recorded batch and weights, every output within 1e-5 relative
(tests/fixtures/golden/README.md); a learner with another clip range or multiplier rate does not.

Where the step's advantages come from is compared too: OmniSafe's buffer on a rollout over the
batch's observations (three chunks: terminated, cut by a time limit, cut by the epoch's end; raw
advantages far from mean 0 and std 1) against the learner connector's batch of the same episodes
(RLlib's phantom rows and GAE, then the cost GAE's standardisation of A^R and centring of A^C over
the real rows): ``buffer/*``, float32 on both sides (golden.BUFFER_ATOL)."""

import numpy as np
import pytest

from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained import cost_gae
from tests.algorithms.golden import BUFFER_ATOL, assert_matches, load, on_policy_step


@pytest.fixture(scope="module")
def fx():
    return load("ppo_lag-omnisafe")


def assert_omnisafes(got: dict, fx) -> None:
    """The step's outputs to 1e-5 relative, the buffer's also to BUFFER_ATOL absolute."""
    assert_matches(got, {k: v for k, v in fx.outputs.items() if not k.startswith("buffer/")})
    assert_matches(got, fx.outputs, only=("buffer/",), atol=BUFFER_ATOL)


def test_the_rollout_s_raw_advantages_are_far_from_standard(fx):
    """OmniSafe's A^R before its buffer's ``get`` had a mean and spread far from 0 and 1 (meta): a
    standardisation left out or changed moves every A^R."""
    raw = fx.meta["rollout_advantages"]["raw_adv_r"]
    assert fx.meta["rollout_chunks"] == [[20, "terminated"], [25, "time_limit"], [19, "epoch_end"]]
    assert abs(raw["mean"]) > 1 and raw["std"] > 3
    assert abs(np.mean(fx.outputs["buffer/adv_r"])) < 1e-6 and np.std(fx.outputs["buffer/adv_r"]) == pytest.approx(1)


def test_the_safety_gym_preset_takes_omnisafes_step(fx):
    assert_omnisafes(on_policy_step(PPOLagConfig, fx), fx)


@pytest.mark.parametrize("fields, differs", [
    ({"clip_param": 0.1}, "grad/actor.mean"),  # the surrogate's clip range
    ({"lagrangian_lr": 0.01}, "nu"),  # the multiplier's rate
    ({"critic_l2": 0.0}, "grad/reward_critic"),  # OmniSafe's use_critic_norm
    ({"lambda_": 0.9}, "buffer/adv_r"),  # GAE's λ
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_omnisafes(on_policy_step(PPOLagConfig, fx, **fields), fx)


def test_the_advantages_standardisation_is_compared(fx, monkeypatch):
    """With the sample std (ddof=1) in place of OmniSafe's population std, every A^R moves by
    √(64/63) − 1 = 0.8%: the comparison names A^R and nothing else."""
    def sample_std(x, mask):
        real = x[mask]
        return np.where(mask, (x - real.mean()) / (real.std(ddof=1) + 1e-8), 0.0).astype(np.float32)

    monkeypatch.setattr(cost_gae, "standardize_on_mask", sample_std)
    with pytest.raises(AssertionError, match=r"differs from the reference's step:\n  buffer/adv_r: [^\n]*$"):
        assert_omnisafes(on_policy_step(PPOLagConfig, fx), fx)
