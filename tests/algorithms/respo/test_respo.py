"""RESPO: its defaults, the reachability targets and its policy loss by hand, ν's step on the
reach-weighted violation (Learners built in this process), and two iterations inside RLlib."""

import math

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.metrics import LEARNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.algorithms.respo import config as C
from lac_rllib.algorithms.respo.config import REACH_PROB_MEAN, REACH_VF_LOSS
from lac_rllib.algorithms.respo.reachability import REACH_PROBS, REACH_TARGETS, reach_targets
from lac_rllib.constrained.metrics import NU, TS_EPISODE_COSTS, iteration_row
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.tasks import get_task

PROBE = "lac/CostProbe-v0"  # obs (1,), action (1,); the episodes below are built by hand
G = 0.99  # γ_p [G]
# p_t of a 10-step path with costs at steps 3 and 7: p_t = max(1[c_t > 0], γ_p·p_{t+1}) by hand,
# the tail after step 9 being 0 (terminated) or V_p(s_10) = 0.4 (truncated, bootstrapped).
TERMINATED = [G**3, G**2, G, 1.0, G**3, G**2, G, 1.0, 0.0, 0.0]
TRUNCATED = [G**3, G**2, G, 1.0, G**3, G**2, G, 1.0, G**2 * 0.4, G * 0.4]


def test_defaults_are_the_authors():
    config = C.RESPOConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert config.nu_init == pytest.approx(math.log1p(math.exp(0.25)))  # p₀ = 0.25, ν = softplus(p)
    assert (config.lagrangian_lr, config.nu_parametrization, config.cost_window, config.lr, config.critic_lr,
            config.reach_critic_lr, config.reach_gamma, config.lambda_, config.clip_param) == \
        (5e-5, "softplus", None, 3e-4, 1e-3, 1e-4, 0.99, 0.97, 0.2)
    assert (config.train_batch_size_per_learner, config.num_epochs, config.minibatch_size, config.target_kl,
            config.kl_stop_late, config.kl_stop_critics, config.grad_clip, config.critic_l2, config.hidden,
            config.log_std_init, config.obs_normalization) == \
        (30_000, 80, None, 0.012, False, False, None, 0.0, (256, 256), -0.5, False)
    # b of ν's step: the task's 25 by default, [G]'s 0 through the field; every lr decays over [G]'s 9e6 steps
    assert config.multiplier_limit == 25.0 and config.training(multiplier_cost_limit=0.0).multiplier_limit == 0.0
    assert config.lr_or_schedule(1e-4) == [[0, 1e-4], [C.RESPO_BUDGET, 0.0]]
    assert config.training(decay_every_lr=False).lr_or_schedule(1e-4) == 1e-4
    docs = C.RESPOConfig.FIELDS.docs()
    assert set(docs) == C.RESPOConfig.FIELDS.names and all(docs.values()) and set(C.PRESETS) == set(C.PRESET_NAMES)


# ----- the reachability targets -----
def test_the_reachability_targets_by_hand():
    """Two chunks in one batch, each 10 real rows and its phantom row: a terminated path (its tail
    0, the phantom's V_p 0.9 unused) and a truncated one (bootstrapped from the phantom's 0.4)."""
    costs = np.zeros(22)
    costs[[3, 7]] = [1.0, 0.5]  # any positive cost is a violation
    costs[[14, 18]] = [2.0, 1.0]
    costs[[10, 21]] = 5.0  # phantom rows' costs are ignored
    mask = np.ones(22, bool)
    mask[[10, 21]] = False
    terminated = np.zeros(22)
    terminated[9] = 1.0
    probs = np.random.default_rng(0).uniform(size=22)  # V_p of real rows does not enter the targets
    probs[[10, 21]] = [0.9, 0.4]
    out = reach_targets(costs, probs, terminated, mask, gamma=G)
    np.testing.assert_allclose(out, [*TERMINATED, 0.0, *TRUNCATED, 0.0], rtol=1e-6)


def episode(length, costs, *, terminated, seed=0):
    """A numpy episode on the probe's spaces, step t costing ``costs[t]``, with the behaviour
    policy's outputs PPO's loss reads."""
    env, rng = get_task(PROBE).make(), np.random.default_rng(seed)
    dist_inputs = rng.normal(size=(length, 2)).astype(np.float32) * 0.3
    actions = rng.normal(size=(length, 1)).astype(np.float32)
    logp = (-0.5 * ((actions[:, 0] - dist_inputs[:, 0]) / np.exp(dist_inputs[:, 1])) ** 2 - dist_inputs[:, 1]
            - 0.5 * np.log(2 * np.pi)).astype(np.float32)
    return SingleAgentEpisode(
        observations=[np.array([t], np.float32) for t in range(length + 1)],
        infos=[{"cost": 0.0}] + [{"cost": float(c)} for c in costs], actions=list(actions),
        rewards=list(rng.normal(size=length)), terminated=terminated,
        extra_model_outputs={Columns.ACTION_DIST_INPUTS: list(dist_inputs), Columns.ACTION_LOGP: list(logp)},
        len_lookback_buffer=0, observation_space=env.observation_space, action_space=env.action_space,
    ).to_numpy()


def learner(**fields):
    """A RESPO Learner on the probe's spaces, built in this process (no Ray)."""
    config = C.RESPOConfig().task(PROBE).training(obs_normalization=False, total_env_steps=1000, **fields)
    return config.build_learner(env=get_task(PROBE).make())


def set_reach_prob(lrn, prob: float) -> None:
    """V_p ≡ ``prob``: the reach critic's output layer's weights 0, its bias logit(prob)."""
    head = [m for m in lrn.module[DEFAULT_MODULE_ID].reach_vf.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        head.weight.zero_(), head.bias.fill_(math.log(prob / (1 - prob)))


def test_the_connector_writes_the_targets_and_v_p_at_collection():
    lrn = learner()
    set_reach_prob(lrn, 0.4)
    costs = np.zeros(10)
    costs[[3, 7]] = 1.0
    batch = lrn._learner_connector(rl_module=lrn.module, batch={}, shared_data={}, metrics=lrn.metrics, episodes=[
        episode(10, costs, terminated=True), episode(10, costs, terminated=False, seed=1)])[DEFAULT_MODULE_ID]
    np.testing.assert_allclose(batch[REACH_TARGETS].numpy(), [*TERMINATED, 0.0, *TRUNCATED, 0.0], rtol=1e-6)
    np.testing.assert_allclose(batch[REACH_PROBS].numpy(), 0.4, rtol=1e-6)
    assert lrn.reachability.safe_fraction[DEFAULT_MODULE_ID] == pytest.approx(0.6)


# ----- the policy loss -----
def test_the_policy_loss_by_hand():
    """−[min(r·A^R·ψ, clip(r)·A^R·ψ) − r·A^C·(ν·ψ + 1 − ψ)]/(1 + ν), ψ = 1 − V_p, on 4 rows: the
    clip active above (row 0) and below (row 1), inactive (rows 2, 3)."""
    nu, eps = 0.7, 0.2
    rows = [  # (r, A^R, A^C, V_p)
        (1.5, 1.0, 2.0, 0.2),
        (0.5, -2.0, -1.0, 0.6),
        (1.1, 0.5, 0.3, 0.0),
        (0.9, -1.0, 4.0, 0.9),
    ]
    expected = []
    for r, a_r, a_c, v_p in rows:
        psi = 1 - v_p
        surrogate = min(r * a_r * psi, min(max(r, 1 - eps), 1 + eps) * a_r * psi)
        expected.append(-(surrogate - r * a_c * (nu * psi + v_p)) / (1 + nu))

    lrn = learner(clip_param=eps)
    module, config = lrn.module[DEFAULT_MODULE_ID], lrn.config.get_config_for_module(DEFAULT_MODULE_ID)
    module.nu.fill_(nu)
    r, a_r, a_c, v_p = (torch.tensor(col, dtype=torch.float32) for col in zip(*rows))
    logp_old = torch.tensor([-1.0, 0.3, -0.2, 0.5])
    batch = {Columns.ACTION_LOGP: logp_old, Postprocessing.ADVANTAGES: a_r, COST_ADVANTAGES: a_c, REACH_PROBS: v_p}
    advantages = lrn.policy_advantages(config, module, batch)
    per_row, term = lrn.policy_loss(DEFAULT_MODULE_ID, config, module, batch, None, logp_old + torch.log(r),
                                    advantages, torch.mean)
    assert term is None
    np.testing.assert_allclose(per_row.detach().numpy(), expected, rtol=1e-6, atol=1e-6)
    assert float(per_row.mean()) == pytest.approx(float(np.mean(expected)), abs=1e-6)
    # reach_weighted=False: ψ ≡ 1, PPO-Lag's loss on A^R − ν·A^C over 1 + ν (V_p no longer matters).
    config.reach_weighted = False
    flat, _ = lrn.policy_loss(DEFAULT_MODULE_ID, config, module, batch, None, logp_old + torch.log(r), advantages,
                              torch.mean)
    unweighted = [-(min(r * a_r, min(max(r, 1 - eps), 1 + eps) * a_r) - r * a_c * nu) / (1 + nu)
                  for r, a_r, a_c, _ in rows]
    np.testing.assert_allclose(flat.detach().numpy(), unweighted, rtol=1e-6, atol=1e-6)


# ----- ν's step -----
def adam(p, grads, lrs):
    """torch.optim.Adam's steps on p by hand (β 0.9, 0.999, ε 1e-8)."""
    m = v = 0.0
    for t, (g, lr) in enumerate(zip(grads, lrs), start=1):
        m, v = 0.9 * m + 0.1 * g, 0.999 * v + 0.001 * g * g
        p -= lr / (1 - 0.9**t) * m / (math.sqrt(v) / math.sqrt(1 - 0.999**t) + 1e-8)
    return p


def softplus(p):
    return math.log1p(math.exp(p))


def test_nu_steps_on_the_reach_weighted_violation_once_before_the_policy(monkeypatch):
    """Adam on p with the gradient −(J_C − b)·mean(1 − V_p), one step per update before any policy
    loss, its lr decaying with the policy's; ``multiplier_cost_limit=0.0`` is [G]'s b = 0."""
    lrn = learner(cost_limit=2.0, lagrangian_lr=0.05, num_epochs=3, minibatch_size=None)
    seen_nu, original = [], type(lrn).policy_loss

    def record(self, module_id, config, module, *args):
        seen_nu.append(float(module.nu))
        return original(self, module_id, config, module, *args)

    monkeypatch.setattr(type(lrn), "policy_loss", record)
    nu, rule = lrn.module[DEFAULT_MODULE_ID].nu, lrn.multipliers[DEFAULT_MODULE_ID].rule
    costs = np.array([0.0, 1.0, 0.0, 0.0, 2.0, 0.0])

    def update(reach_prob, episode_costs, lifetime):
        set_reach_prob(lrn, reach_prob)  # V_p at collection ≡ reach_prob (the update trains it on)
        seen_nu.clear()
        lrn.update(episodes=[episode(6, costs, terminated=True)], minibatch_size=None, num_epochs=3,
                   timesteps={TS_EPISODE_COSTS: episode_costs, NUM_ENV_STEPS_SAMPLED_LIFETIME: lifetime})

    update(0.5, [8.0, 12.0], 250)  # J_C 10, mean ψ 0.5: g = −(10 − 2)·0.5
    assert rule.adam.t == 1 and rule.adam.m == pytest.approx(0.1 * -4.0)
    assert float(nu) == pytest.approx(softplus(adam(0.25, [-4.0], [0.05])), abs=1e-6)
    assert seen_nu == [float(nu)] * 3  # stepped before the first policy loss, once for 3 epochs
    # J_C 1 < b, mean ψ 0.2: g = −(1 − 2)·0.2; the policy's lr (and so ν's) is at 1 − 250/1000
    update(0.8, [1.0], 500)
    assert lrn.reachability.safe_fraction[DEFAULT_MODULE_ID] == pytest.approx(0.2)
    assert float(nu) == pytest.approx(softplus(adam(0.25, [-4.0, 0.2], [0.05, 0.05 * 0.75])), abs=1e-6)

    authors = learner(cost_limit=2.0, multiplier_cost_limit=0.0, lagrangian_lr=0.05, num_epochs=1)
    set_reach_prob(authors, 0.5)
    authors.update(episodes=[episode(6, costs, terminated=True)], minibatch_size=None, num_epochs=1,
                   timesteps={TS_EPISODE_COSTS: [1.0]})
    # b = 0: J_C 1 is a violation, g = −(1 − 0)·0.5 (with b = 2 it would be +0.5 and ν would fall)
    assert authors.multipliers[DEFAULT_MODULE_ID].rule.adam.m == pytest.approx(0.1 * -0.5)
    assert float(authors.module[DEFAULT_MODULE_ID].nu) == pytest.approx(softplus(adam(0.25, [-0.5], [0.05])),
                                                                        abs=1e-6)


# ----- inside RLlib -----
def test_two_iterations_report_respo_s_keys_and_v_p_stays_on_the_learner(ray_session):
    algo = C.RESPOConfig.build("lac/PointHazard-v0", 0, {"train_batch_size_per_learner": 400, "minibatch_size": 100,
                                                    "num_epochs": 2, "num_envs_per_env_runner": 1},
                          timesteps=20_000).build_algo()
    try:
        assert algo.config.ALGO == "respo"
        results = [algo.train() for _ in range(2)]
        learner_module = algo.learner_group._learner.module[DEFAULT_MODULE_ID]
        assert hasattr(learner_module, "reach_vf") and not hasattr(algo.env_runner.module, "reach_vf")
    finally:
        algo.stop()
    row = iteration_row(results[-1], C.RESPOConfig.REPORTED_KEYS)
    assert set(C.RESPOConfig.REPORTED_KEYS) <= row.keys()
    assert all(math.isfinite(v) for v in row.values()), row
    assert 0 < row[REACH_PROB_MEAN] < 1 and row[REACH_VF_LOSS] > 0
    assert row[NU] != pytest.approx(C.NU_INIT)  # episodes completed: ν stepped
    # the reach critic's lr decays with the policy's: 800 of 20k steps → 0.96 of the tiny preset's 1e-3
    lr = results[-1][LEARNER_RESULTS][DEFAULT_MODULE_ID]["reach_critic_learning_rate"]
    assert lr == pytest.approx(1e-3 * (1 - 800 / 20_000), rel=1e-3)
