"""CUP against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md): the multiplier's step,
stage 1's minibatch (both critics; the actor's PPO-clipped surrogate on A^R), then stage 2's
(the actor alone on ν·(1 − γλ)/(1 − γ)·r·A^C + KL(π_θ ‖ π_ref), clip, the same Adam), every output
within 1e-5 relative: stage 1's three losses (the actor's surrogate, each critic's MSE + 0.001·Σθ²
as OmniSafe logs them), every gradient and parameter after each stage, stage 2's loss, ν.
Stage 2's reference policy is the recorded one (the batch's behaviour policy, as OmniSafe's
``_p_dist`` after some minibatches of its loop): the KL term then has a gradient."""

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, VF_LOSS_KEY

from lac_rllib.algorithms.cup.config import PROJECTION_LOSS, CUPConfig
from lac_rllib.algorithms.cup.learner import Projection
from lac_rllib.algorithms.cup.row_index import ROW_INDEX
from lac_rllib.constrained.metrics import COST_VF_LOSS
from tests.algorithms.golden import (
    OMNISAFE_ON_POLICY,
    assert_matches,
    build_on_policy,
    load,
    minibatch_step,
    multiplier_step,
    on_policy_batch,
    ours,
)


@pytest.fixture(scope="module")
def fx():
    return load("cup-omnisafe")


def cup_step(fx, **fields) -> dict:
    """Both stages through the learner's hooks, one minibatch each (the whole recorded batch)."""
    learner = build_on_policy(CUPConfig, fx, **fields)
    mid, module = DEFAULT_MODULE_ID, learner.module[DEFAULT_MODULE_ID].unwrapped()
    batch = {**on_policy_batch(fx), ROW_INDEX: torch.arange(len(fx.inputs["obs"]))}
    learner.stage_epochs = (1, 1)
    nu = multiplier_step(learner, fx)
    learner.cost_gae.last_batch = {mid: batch}  # the whole batch the connector would keep
    reverse = {v: k for k, v in OMNISAFE_ON_POLICY.items()}
    config = learner.config.get_config_for_module(mid)
    l2 = {net: config.critic_l2 * sum(float((p.detach() ** 2).sum()) for n, p in module.named_parameters()
                                      if ours(n, reverse).startswith(net)) for net in ("reward_critic", "cost_critic")}
    stage1 = minibatch_step(learner, batch)
    peek = lambda key: float(torch.as_tensor(learner.metrics.peek((mid, key))).detach())  # noqa: E731
    out = {"nu": nu, "loss_pi": peek(POLICY_LOSS_KEY), "loss_reward_critic": peek(VF_LOSS_KEY) + l2["reward_critic"],
           "loss_cost_critic": peek(COST_VF_LOSS) + l2["cost_critic"]}
    out.update({f"grad/{ours(n, reverse)}": g.numpy() for n, g in stage1.items()})
    out.update({f"after/{ours(n, reverse)}": p.detach().clone().numpy() for n, p in module.named_parameters()})
    # Stage 2 from the recorded reference policy, its epoch's check already made.
    learner.projections[mid] = Projection(first_epoch=1, epochs=1, reference=batch[Columns.ACTION_DIST_INPUTS],
                                          checked=1)
    stage2 = minibatch_step(learner, batch)
    out["stage2/loss_pi_c"] = float(learner.metrics.peek((mid, PROJECTION_LOSS)))
    out.update({f"stage2/grad/{ours(n, reverse)}": g.numpy() for n, g in stage2.items()})
    out.update({f"stage2/after/{ours(n, reverse)[len('actor.'):]}": p.detach().numpy()
                for n, p in module.named_parameters() if ours(n, reverse).startswith("actor.")})
    return out


def test_both_stages_are_omnisafes_step(fx):
    assert_matches(cup_step(fx), fx.outputs)


@pytest.mark.parametrize("fields, differs", [({"gamma": 0.995}, "stage2/loss_pi_c"),
                                             ({"lagrangian_lr": 0.01}, "nu"),
                                             ({"clip_param": 0.1}, r"\n  loss_pi: "),  # stage 1's surrogate
                                             ({"critic_l2": 0.0}, r"\n  loss_reward_critic: ")])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(cup_step(fx, **fields), fx.outputs)
