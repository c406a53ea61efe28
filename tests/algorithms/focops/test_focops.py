"""FOCOPS without Ray: its loss against a hand computation on a 4-row batch, the indicator that
drops a row beyond η, the fixed bound on ν, the ``paper`` preset's ν sequence and advantages."""

import math

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms.focops.config import FOCOPSConfig
from lac_rllib.constrained.metrics import TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.tasks import get_task

PROBE = "lac/CostProbe-v0"  # obs (1,), action (1,)


def learner(**fields):
    config = FOCOPSConfig().task(PROBE).training(obs_normalization=False, total_env_steps=1000, **fields)
    return config.build_learner(env=get_task(PROBE).make())


def gaussian_logp(a, mean, log_std):
    return -((a - mean) ** 2) / (2 * math.exp(2 * log_std)) - log_std - 0.5 * math.log(2 * math.pi)


def gaussian_kl(mean, log_std, ref_mean, ref_log_std):
    """KL(N(mean, σ²) ‖ N(ref_mean, σ_ref²)), by hand."""
    var, ref_var = math.exp(2 * log_std), math.exp(2 * ref_log_std)
    return ref_log_std - log_std + (var + (mean - ref_mean) ** 2) / (2 * ref_var) - 0.5


def test_the_loss_is_eq_11_and_drops_the_row_beyond_eta():
    lrn = learner(focops_lam=1.5, focops_eta=0.02, focops_indicator="per_row")
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    config = lrn.config.get_config_for_module(DEFAULT_MODULE_ID)
    logits = torch.tensor([[0.10, -0.2], [0.00, 0.0], [0.30, 0.1], [-0.5, -0.3]], requires_grad=True)
    # The reference (behaviour) policy: rows 0, 1, 3 within η = 0.02 of the policy, row 2 far off.
    reference = torch.tensor([[0.12, -0.2], [0.05, 0.02], [1.50, 0.1], [-0.45, -0.32]])
    actions = torch.tensor([[0.2], [-0.1], [0.5], [-0.7]])
    advantages = torch.tensor([1.0, -2.0, 3.0, 0.5])
    behaviour_logp = torch.tensor([gaussian_logp(a, m, s)
                                   for a, (m, s) in zip(actions[:, 0].tolist(), reference.tolist())])
    logp = torch.stack([-((actions[i, 0] - logits[i, 0]) ** 2) / (2 * torch.exp(2 * logits[i, 1])) - logits[i, 1]
                        - 0.5 * math.log(2 * math.pi) for i in range(4)])
    batch = {Columns.ACTION_DIST_INPUTS: reference, Columns.ACTION_LOGP: behaviour_logp, Columns.ACTIONS: actions}
    rows, term = lrn.policy_loss(DEFAULT_MODULE_ID, config, module, batch, logits, logp, advantages,
                                 masked_mean=lambda x: x.mean())
    expected = []
    for i in range(4):
        kl = gaussian_kl(*logits[i].tolist(), *reference[i].tolist())
        ratio = math.exp(logp[i].item() - behaviour_logp[i].item())
        expected.append((kl - ratio * advantages[i].item() / 1.5) * float(kl <= 0.02))
    assert term is None
    np.testing.assert_allclose(rows.detach().numpy(), expected, atol=1e-6)
    assert expected[2] == 0.0 and all(e != 0.0 for i, e in enumerate(expected) if i != 2)
    rows.sum().backward()
    assert torch.all(logits.grad[2] == 0) and torch.all(logits.grad[[0, 1, 3]].abs().sum(-1) > 0)


def test_the_advantage_is_divided_by_one_plus_nu_unless_the_paper_preset():
    batch = {Postprocessing.ADVANTAGES: torch.tensor([1.0, -1.0]), COST_ADVANTAGES: torch.tensor([2.0, 4.0])}
    for preset, expected in ((None, [(1 - 1.4) / 1.7, (-1 - 2.8) / 1.7]), ("paper", [1 - 1.4, -1 - 2.8])):
        lrn = learner(**({"preset": preset} if preset else {}))
        module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
        module.nu.fill_(0.7)
        got = lrn.policy_advantages(lrn.config.get_config_for_module(DEFAULT_MODULE_ID), module, batch)
        np.testing.assert_allclose(got.numpy(), expected, rtol=1e-6)


def test_the_fixed_bound_holds_nu_at_2_under_a_cost_far_over_the_limit():
    lrn = learner(lagrangian_lr=0.5, cost_limit=2.0)  # Adam: ν climbs by ~0.5 a step
    for _ in range(20):
        lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [500.0]})
    assert float(lrn.module[DEFAULT_MODULE_ID].nu) == 2.0
    unbounded = learner(lagrangian_lr=0.5, cost_limit=2.0, nu_max=None)
    for _ in range(20):
        unbounded.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [500.0]})
    assert float(unbounded.module[DEFAULT_MODULE_ID].nu) > 5.0


def test_the_paper_presets_nu_is_the_clipped_gradient_step_on_this_batchs_episodes():
    """[F] focops_main.py: ν ← clip(ν + 0.01·(J̄_C − b), 0, 2) from 0, J̄_C this batch's mean."""
    lrn = learner(preset="paper", cost_limit=10.0)
    nu, seen = 0.0, []
    for costs in ([30.0], [20.0, 40.0], [5.0], [400.0], [0.0], [], [9.0]):
        lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: costs})
        if costs:
            nu = min(2.0, max(0.0, nu + 0.01 * (float(np.mean(costs)) - 10.0)))
        seen.append(float(lrn.module[DEFAULT_MODULE_ID].nu))
        assert seen[-1] == pytest.approx(nu, abs=1e-6)  # ν is a float32 buffer
        nu = seen[-1]
    assert seen[:5] == pytest.approx([0.2, 0.4, 0.35, 2.0, 1.9], abs=1e-6)


def test_the_paper_preset_standardises_the_cost_advantages():
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    env = get_task(PROBE).make()
    rng = np.random.default_rng(0)
    length = 9
    episode = SingleAgentEpisode(
        observations=[np.array([t], np.float32) for t in range(length + 1)],
        infos=[{"cost": 0.0}] + [{"cost": float(3 * t)} for t in range(length)],
        actions=list(rng.normal(size=(length, 1)).astype(np.float32)),
        rewards=list(rng.normal(size=length)), terminated=True,
        extra_model_outputs={Columns.ACTION_DIST_INPUTS: list(rng.normal(size=(length, 2)).astype(np.float32)),
                             Columns.ACTION_LOGP: list(rng.normal(size=length).astype(np.float32))},
        len_lookback_buffer=0, observation_space=env.observation_space, action_space=env.action_space).to_numpy()
    for preset, std in ((None, None), ("paper", 1.0)):
        lrn = learner(**({"preset": preset} if preset else {}))
        batch = lrn._learner_connector(rl_module=lrn.module, batch={}, episodes=[episode], shared_data={},
                                       metrics=lrn.metrics)[DEFAULT_MODULE_ID]
        a_c = batch[COST_ADVANTAGES][batch[Columns.LOSS_MASK]].numpy()
        assert abs(a_c.mean()) < 1e-5
        assert (a_c.std() == pytest.approx(1.0, rel=1e-4)) if std else a_c.std() > 3.0
