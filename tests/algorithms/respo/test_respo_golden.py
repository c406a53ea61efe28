"""RESPO against its authors' code (milanganai.github.io NeurIPS2023/code@7c194db; the fixture
respo-authors.npz, benchmarks/golden/respo_authors.py): their ``update()`` with one step of each
loop and the learner's minibatch step, from the same weights and batch, agree on every recorded
output within 1e-5 relative: the penalty's Adam step on −p·(J_C − 0)·mean(1 − V_p) (respo.py:172,
223-229; its gradient is read back from the project's Adam's first moment), the policy's loss
−[min(r·A^R·ψ, clip(r)·A^R·ψ) − r·A^C·(νψ + 1 − ψ)]/(1 + ν) (:147-169) and Adam step, and the
three critics' MSE and Adam steps, V_p's at 1e-4 (:185-203, 257-273).

The documented departures (docs/baselines.md; baselines-audit R2-R7) and this step:
- R2, b of ν's step: [G] 0 (:153); ``multiplier_cost_limit=0.0`` reproduces it (the default, the
  task's limit, fails below, naming grad/penalty_param);
- R4, V_p's target at a cut path's end: an input of the step here ([G] computes it at collection,
  finish_path :58-89); ``test_the_reach_targets_recursion_is_theirs`` shows the recursion is theirs
  and the tail the only difference (R4: [G] float(V_C(s_T) > 0), here V_p(s_T));
- R5, critic targets (discounted returns-to-go in [G], GAE-λ returns here): inputs of the step;
- R6, the KL stop: checked before a step in both, outside the minibatch step (their estimate at
  this step is 0.0072 < 0.012: the step is taken);
- R3, R7: the advantages are inputs; the recipe's sizes do not enter one step.
Nothing is excluded from the step's comparison."""

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, VF_LOSS_KEY

from lac_rllib.algorithms.respo.config import REACH_VF_LOSS, RESPOConfig
from lac_rllib.algorithms.respo.reachability import REACH_PROBS, REACH_TARGETS, reach_targets
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import COST_VF_LOSS, TS_EPISODE_COSTS
from tests.algorithms.golden import assert_matches, load, minibatch_step, on_policy_batch
from tests.algorithms.golden_sources import RESPO_AUTHORS, build, in_reference_names

MID = DEFAULT_MODULE_ID
THEIRS = {"multiplier_cost_limit": 0.0}  # [G] compute_loss_pi: cost_limit = 0 (respo.py:153)


@pytest.fixture(scope="module")
def fx():
    return load("respo-authors")


def respo_step(fx, **fields) -> dict:
    """The fixture's step taken by the learner (the task's preset), under the authors' names."""
    learner = build(RESPOConfig, fx, RESPO_AUTHORS, **{**THEIRS, **fields})
    i = fx.inputs
    learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [float(i["ep_cost"])]})
    learner.reachability.safe_fraction[MID] = float(1.0 - np.mean(i["reach_probs"]))  # the connector's ψ̄
    batch = {**on_policy_batch(fx), REACH_PROBS: torch.as_tensor(i["reach_probs"]),
             REACH_TARGETS: torch.as_tensor(i["reach_targets"])}
    grads = minibatch_step(learner, batch)
    peek = lambda key: float(torch.as_tensor(learner.metrics.peek((MID, key))).detach())  # noqa: E731
    adam = learner.multipliers[MID].rule.adam  # its first step: m = (1 − β₁)·g, g = −(J_C − b)·ψ̄
    return {"penalty_param": learner.multipliers[MID].rule.p, "nu": float(learner.module[MID].unwrapped().nu),
            "grad/penalty_param": adam.m / (1.0 - adam.betas[0]), "loss_pi": peek(POLICY_LOSS_KEY),
            "loss_reward_critic": peek(VF_LOSS_KEY), "loss_cost_critic": peek(COST_VF_LOSS),
            "loss_reach_critic": peek(REACH_VF_LOSS), **in_reference_names(learner, grads, RESPO_AUTHORS, fx)}


def test_the_fixture_is_the_authors_step(fx):
    assert fx.meta["reference_version"] == "7c194db2098d28dee7336c493e3471c14c0186fe"
    assert fx.meta["policy_stepped"] and fx.meta["approx_kl_at_step"] <= 1.2 * 0.01  # their KL check passed
    assert 0.05 < fx.meta["clip_fraction_at_step"] < 0.5  # the reward surrogate's clip acts on some rows
    assert 0.0 < np.mean(fx.inputs["cost"]) < 0.5 and fx.inputs["tail_value_c"] > 0  # a cut path, [G] tail 1


def test_the_step_is_the_authors(fx):
    got = respo_step(fx)
    assert set(got) == set(fx.outputs)
    assert_matches(got, fx.outputs)


def chunked(fx, obs_t: np.ndarray):
    """The fixture's two paths as the learner connector sees them: each path's rows, then its
    phantom row (masked; the second's observation is s_T)."""
    first, second = fx.meta["paths"]
    obs, zero = np.asarray(fx.inputs["obs"]), np.zeros(1)
    return {Columns.OBS: torch.as_tensor(np.concatenate([obs[:first], obs_t[None], obs[first:], obs_t[None]])),
            COSTS: torch.as_tensor(np.concatenate([fx.inputs["cost"][:first], zero, fx.inputs["cost"][first:], zero])),
            Columns.TERMINATEDS: torch.as_tensor(np.concatenate([fx.inputs["terminated"][:first], [False],
                                                                 fx.inputs["terminated"][first:], [False]])),
            Columns.LOSS_MASK: torch.as_tensor([True] * first + [False] + [True] * second + [False])}


def test_the_reach_targets_recursion_is_theirs(fx):
    """[G] finish_path's p_t = max(1[c_t > 0], 0.99·p_{t+1}) with p_T = 0 at the terminal and
    float(V_C(s_T) > 0) at the cut (respo.py:67-89): reach_targets() given their tail gives their
    targets on every row; the connector's own tail V_p(s_T) (R4) changes the cut path's rows only."""
    first, second = fx.meta["paths"]
    learner = build(RESPOConfig, fx, RESPO_AUTHORS, **THEIRS)
    columns = chunked(fx, np.asarray(fx.inputs["obs_T"]))
    learner.reachability(rl_module=learner.module, batch={MID: columns}, episodes=[])
    mask = columns[Columns.LOSS_MASK].numpy()
    probs = columns[REACH_PROBS].numpy()
    np.testing.assert_allclose(probs[mask], fx.inputs["reach_probs"], rtol=1e-5)  # V_p at collection
    assert learner.reachability.safe_fraction[MID] == pytest.approx(1 - np.mean(fx.inputs["reach_probs"]), rel=1e-6)
    theirs_tail = probs.copy()
    theirs_tail[-1] = float(fx.inputs["tail_value_c"] > 0)  # [G] :67, :71
    ours = reach_targets(columns[COSTS].numpy(), theirs_tail, columns[Columns.TERMINATEDS].numpy(), mask, gamma=0.99)
    np.testing.assert_allclose(ours[mask], fx.inputs["reach_targets"], rtol=1e-6)
    own = columns[REACH_TARGETS].numpy()[mask]  # the connector's: V_p(s_T) at the cut (R4)
    differs = np.flatnonzero(~np.isclose(own, fx.inputs["reach_targets"], rtol=1e-6))
    assert len(differs) and differs.min() >= first, differs  # the terminal path's targets are theirs


@pytest.mark.parametrize("fields, differs", [
    ({"multiplier_cost_limit": None}, "grad/penalty_param"),  # b = the task's 25 (R2's default)
    ({"lagrangian_lr": 1e-4}, r"\n  penalty_param:"),
    ({"reach_weighted": False}, "loss_pi"),
    ({"clip_param": 0.1}, r"grad/pi\.mu_net"),
    ({"reach_critic_lr": 1e-3}, r"after/vp\.v_net"),
    ({"critic_l2": 1e-3}, r"grad/v\.v_net"),
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(respo_step(fx, **fields), fx.outputs)


def test_the_comparison_sees_a_flipped_sign(fx):
    """The cost advantage's sign flipped in the batch: the policy's loss and gradient differ."""
    flipped = type(fx)(fx.name, fx.meta, {**fx.inputs, "adv_c": -np.asarray(fx.inputs["adv_c"])}, fx.before,
                       fx.outputs)
    with pytest.raises(AssertionError, match=r"loss_pi(.|\n)*grad/pi\.log_std"):
        assert_matches(respo_step(flipped), fx.outputs)
