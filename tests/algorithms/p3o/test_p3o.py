"""P3O without Ray: its penalty against a hand computation on a 4-row batch (0 with a 0 gradient
when the cost surrogate plus the gap is negative), the loss beside PPO's, ``nu`` as the active weight."""

import math

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms import registry
from lac_rllib.algorithms.p3o.config import COST_PENALTY, P3OConfig
from lac_rllib.constrained.metrics import NU, TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.tasks import get_task

PROBE = "lac/CostProbe-v0"


def learner(**fields):
    config = P3OConfig().task(PROBE).training(obs_normalization=False, total_env_steps=1000, **fields)
    return config.build_learner(env=get_task(PROBE).make())


def _batch():
    logp_old = torch.tensor([-1.0, -0.5, -2.0, -1.2])
    logp = (logp_old + torch.tensor([0.1, -0.3, 0.05, 0.4])).requires_grad_(True)
    batch = {Columns.ACTION_LOGP: logp_old, Postprocessing.ADVANTAGES: torch.tensor([1.0, -1.0, 0.5, 2.0]),
             COST_ADVANTAGES: torch.tensor([3.0, -1.0, 2.0, -4.0])}
    return batch, logp


@pytest.mark.parametrize("j_c, active", [(40.0, True), (5.0, False)])
def test_the_penalty_is_kappa_relu_of_the_cost_surrogate_plus_the_gap(j_c, active):
    lrn = learner(kappa=20.0, cost_limit=10.0, clip_param=0.2)
    lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [j_c]})
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    config = lrn.config.get_config_for_module(DEFAULT_MODULE_ID)
    batch, logp = _batch()
    advantages = lrn.policy_advantages(config, module, batch)
    rows, penalty = lrn.policy_loss(DEFAULT_MODULE_ID, config, module, batch, None, logp, advantages,
                                    masked_mean=lambda x: x.mean())
    ratio = [math.exp(d) for d in (0.1, -0.3, 0.05, 0.4)]
    a_r, a_c = [1.0, -1.0, 0.5, 2.0], [3.0, -1.0, 2.0, -4.0]
    clipped = [-min(r * a, min(max(r, 0.8), 1.2) * a) for r, a in zip(ratio, a_r)]
    surrogate = float(np.mean([r * a for r, a in zip(ratio, a_c)]))
    assert surrogate + j_c - 10.0 > 0 if active else surrogate + j_c - 10.0 < 0
    np.testing.assert_allclose(rows.detach().numpy(), clipped, atol=1e-6)  # A^R alone: ν plays no part
    assert float(penalty) == pytest.approx(20.0 * max(surrogate + j_c - 10.0, 0.0), abs=1e-5)
    (rows.mean() + penalty).backward()
    grad_penalty = [20.0 * r * a / 4 for r, a in zip(ratio, a_c)] if active else [0.0] * 4
    grad_clipped = [(-r * a if 0.8 < r < 1.2 or r * a < min(max(r, 0.8), 1.2) * a else 0.0) / 4
                    for r, a in zip(ratio, a_r)]
    np.testing.assert_allclose(logp.grad.numpy(), np.add(grad_penalty, grad_clipped), atol=1e-5)
    assert lrn.metrics.peek((DEFAULT_MODULE_ID, NU)) == (20.0 if active else 0.0)
    assert lrn.metrics.peek((DEFAULT_MODULE_ID, COST_PENALTY)) == pytest.approx(float(penalty))


def test_no_episode_yet_no_penalty_and_nu_stays_0():
    lrn = learner(cost_limit=0.0)
    lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: []})
    config = lrn.config.get_config_for_module(DEFAULT_MODULE_ID)
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    batch, logp = _batch()
    _, penalty = lrn.policy_loss(DEFAULT_MODULE_ID, config, module, batch, None, logp, batch[Postprocessing.ADVANTAGES],
                                 masked_mean=lambda x: x.mean())
    assert penalty is None
    for cost in (100.0, 300.0):
        lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [cost]})
    assert float(module.nu) == 0.0  # no multiplier: the module's ν never moves


def test_p3o_has_no_multiplier_fields():
    names = registry.algo_config("p3o").FIELDS.names
    assert {"kappa", "clip_param", "cost_window", "target_kl"} <= names
    assert not names & {"nu_init", "lagrangian_lr", "nu_max", "nu_parametrization", "nu_optimizer"}
    with pytest.raises(ValueError, match="lagrangian_lr"):
        registry.parse_sets("p3o", ["lagrangian_lr=0.1"])
    assert P3OConfig().task("lac/PointHazard-v0").num_epochs == 10  # [O] P3O.yaml update_iters
