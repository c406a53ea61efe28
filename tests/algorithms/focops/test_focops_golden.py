"""FOCOPS against OmniSafe 0.5.0's own step (tests/fixtures/golden/README.md): with
``focops_indicator="broadcast"`` (the default and the ``omnisafe`` preset) every output is
OmniSafe's within 1e-5 relative, the multiplier's bounded Adam step, both critics and the actor's
B × B-broadcast loss [O focops.py:103-107]; the paper's per-row loss (the ``paper`` preset's) takes
another actor step on the same batch, and the test says where."""

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns

from lac_rllib.algorithms.focops.config import FOCOPSConfig
from lac_rllib.families.on_policy.projection import gaussian_kl
from tests.algorithms.golden import assert_matches, build_on_policy, load, on_policy_batch, on_policy_step


@pytest.fixture(scope="module")
def fx():
    return load("focops-omnisafe")


def test_the_fixture_has_rows_on_both_sides_of_eta(fx):
    """Else broadcast and per-row coincide and the test below could not tell them apart."""
    learner = build_on_policy(FOCOPSConfig, fx)
    batch = on_policy_batch(fx)
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    with torch.no_grad():
        kl = gaussian_kl(module.action_dist_inputs(batch[Columns.OBS]), batch[Columns.ACTION_DIST_INPUTS]).numpy()
    inside = np.mean(kl <= fx.meta["algo_cfgs"]["focops_eta"])
    assert 0.05 < inside < 0.95, inside  # 8 of the 64 rows inside η


@pytest.mark.parametrize("fields", [{}, {"focops_indicator": "broadcast"}, {"preset": "omnisafe"}])
def test_the_broadcast_loss_is_omnisafes_step(fx, fields):
    assert_matches(on_policy_step(FOCOPSConfig, fx, **fields), fx.outputs)


def test_the_per_row_loss_differs_in_the_actor_only(fx):
    got = on_policy_step(FOCOPSConfig, fx, focops_indicator="per_row")
    assert_matches(got, fx.outputs, only=("nu", "loss_reward_critic", "loss_cost_critic", "grad/reward_critic",
                                          "grad/cost_critic", "after/reward_critic", "after/cost_critic"))
    with pytest.raises(AssertionError, match=r"grad/actor\.mean\.0\.weight"):
        assert_matches(got, fx.outputs, only=("grad/actor",))


@pytest.mark.parametrize("fields, differs", [({"focops_lam": 1.0}, "loss_pi"), ({"focops_eta": 0.05}, "loss_pi"),
                                             ({"nu_divides_advantage": False}, "grad/actor")])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(on_policy_step(FOCOPSConfig, fx, focops_indicator="broadcast", **fields), fx.outputs)
