"""FOCOPS's ``paper`` preset against the paper's own code, ymzhang01/focops (the fixture
focops-paper.npz, benchmarks/golden/focops_authors.py): one update_params step of theirs with one
64-row minibatch (focops_main.py:74-152) and the learner's, from the same weights and batch, agree
on every recorded output within 1e-5 relative: ν's clipped SGD step from 0 on the batch's episode
cost (:97-102), both critics' MSE + 1e-3·Σθ² and Adam steps (:111-130), the per-row loss
(KL − r·(A^R − ν·A^C)/λ_F)·1[KL ≤ η] averaged (:133-139) and the policy's Adam step (:140-143).

The PAPER preset's listed approximations and this step:
- critics' lr decay [F LambdaLR on all three, :209-212]: the step is iteration 0, factor 1 in both;
- clip on the policy only [F :142] against each network's here: no gradient norm reaches 40 in
  this step (``test_no_clip_binds``), so neither clip acts;
- the epoch KL's direction [F :147-151]: checked after an epoch, outside the minibatch step;
- J_C discounted [F data_generator.py:76, 137]: what J_C is, not how ν steps on it; the fixture's
  ep_cost is fed as is to both.
None of them changes this step: nothing is excluded from the comparison."""

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, VF_LOSS_KEY

from lac_rllib.algorithms.focops.config import FOCOPSConfig
from lac_rllib.constrained.metrics import COST_VF_LOSS, TS_EPISODE_COSTS
from tests.algorithms.golden import assert_matches, load, minibatch_step, on_policy_batch
from tests.algorithms.golden_sources import FOCOPS_AUTHORS, build, critic_l2, in_reference_names


@pytest.fixture(scope="module")
def fx():
    return load("focops-paper")


def paper_step(fx, **fields) -> dict:
    """The fixture's step taken by the ``paper`` preset's learner, under the authors' names."""
    hyper = fx.meta["hyperparameters"]  # the run's budget: the policy's lr decays over it [F :209]
    fields = {"total_env_steps": hyper["max_iter_num"] * hyper["batch_size"], **fields}
    learner = build(FOCOPSConfig, fx, FOCOPS_AUTHORS, preset="paper", **fields)
    l2 = {net: critic_l2(learner, FOCOPS_AUTHORS, net) for net in ("value_net", "cvalue_net")}
    learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [float(fx.inputs["ep_cost"])]})
    grads = minibatch_step(learner, on_policy_batch(fx))
    peek = lambda key: float(torch.as_tensor(learner.metrics.peek((DEFAULT_MODULE_ID, key))).detach())  # noqa: E731
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    return {"nu": float(module.nu), "loss_pi": peek(POLICY_LOSS_KEY),
            "loss_reward_critic": peek(VF_LOSS_KEY) + l2["value_net"],
            "loss_cost_critic": peek(COST_VF_LOSS) + l2["cvalue_net"],
            **in_reference_names(learner, grads, FOCOPS_AUTHORS, fx)}


def test_the_fixture_is_the_authors_step(fx):
    assert fx.meta["reference_version"] == "fc92fcee1500d1b0dbe45a23c66188f22e463371"
    assert fx.meta["preset"] == "paper" and fx.meta["cost_limit"] == 24.516  # environment.py: Swimmer-v3
    assert 0.1 < fx.meta["rows_inside_eta"] / fx.meta["rows"] < 0.9  # the indicator cuts: 35 of 64 inside η
    assert 0 < fx.outputs["nu"] < fx.meta["hyperparameters"]["nu_max"]  # ν moved, unclipped


def test_no_clip_binds(fx):
    """[F] clips the policy's gradient at 40 (:142), the project each network's: equal steps
    only while no norm reaches 40, as in this step."""
    assert max(fx.meta["grad_norms_before_clip"].values()) < 40.0


def test_the_paper_preset_is_the_authors_step(fx):
    got = paper_step(fx)
    assert set(got) == set(fx.outputs)
    assert_matches(got, fx.outputs)


@pytest.mark.parametrize("fields, differs", [
    ({"nu_divides_advantage": True}, r"grad/policy\.mlp_net"),  # OmniSafe's A/(1 + ν)
    ({"focops_indicator": "broadcast"}, r"grad/policy\.mlp_net"),  # OmniSafe's B × B mask
    ({"focops_lam": 1.0}, "loss_pi"),
    ({"lagrangian_lr": 0.02}, r"\n  nu:"),
    ({"critic_l2": 0.0}, "loss_reward_critic"),
    ({"critic_lr": 1e-3}, r"after/value_net"),
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(paper_step(fx, **fields), fx.outputs)


def test_the_comparison_sees_a_flipped_sign(fx):
    """The cost advantage's sign flipped in the batch: the policy's gradient and loss differ."""
    flipped = type(fx)(fx.name, fx.meta, {**fx.inputs, "adv_c": -np.asarray(fx.inputs["adv_c"])}, fx.before,
                       fx.outputs)
    with pytest.raises(AssertionError, match=r"loss_pi(.|\n)*grad/policy\.logstd_layer"):
        assert_matches(paper_step(flipped), fx.outputs)
