"""SAC-Lag (lac_rllib/algorithms/sac_lag): OmniSafe's targets and actor loss against hand-written
formulas, the policy delay, λ's checkpoint, the cost column and the config's interface."""

import numpy as np
import pytest
import torch
from conftest import train_batch
from gymnasium.spaces import Box
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.algorithms import registry
from lac_rllib.algorithms.sac_lag import module as M
from lac_rllib.algorithms.sac_lag.algorithm import SACLag
from lac_rllib.algorithms.sac_lag.config import BF16_MIN_WIDTH, FIELDS, PRESETS, SACLagConfig
from lac_rllib.algorithms.sac_lag.learner import ACTOR, actor_loss, critic_targets
from lac_rllib.algorithms.sac_lag.module import SACLagTorchRLModule
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import ACTOR_LOSS, ENV_STEPS, EPISODE_COST, NU, TS_EPISODE_COSTS
from lac_rllib.tasks import get_task

OBS, ACT, B = 5, 2, 64
LOW, HIGH = np.array([-1.0, -0.5], np.float32), np.array([1.0, 2.0], np.float32)  # not [-1, 1]: the map shows
PROBE = "lac/CostProbe-v0"  # cost of step t = 2t + 1, obs = t, reward = −t, 7-step episodes


def _module(seed=0, **overrides) -> SACLagTorchRLModule:
    torch.manual_seed(seed)  # the same weights whatever ran before in this process (xdist orders vary)
    cfg = {**FIELDS.defaults, "actor_hidden": (32, 32), "critic_hidden": (32, 32), **overrides}
    module = SACLagTorchRLModule(observation_space=Box(-np.inf, np.inf, (OBS,), np.float32),
                                 action_space=Box(LOW, HIGH, dtype=np.float32), model_config=cfg)
    module.make_target_networks()
    # Targets away from the online critics, so a target taken from the wrong network shows.
    with torch.no_grad():
        for p in [*module.target_reward_critics.parameters(), *module.target_cost_critic.parameters()]:
            p.add_(0.3 * torch.randn_like(p))
    return module


def _batch(seed=0, n=B, obs_dim=OBS, low=LOW, high=HIGH) -> dict:
    g = torch.Generator().manual_seed(seed)
    return {
        Columns.OBS: torch.randn(n, obs_dim, generator=g), Columns.NEXT_OBS: torch.randn(n, obs_dim, generator=g),
        Columns.ACTIONS: torch.rand(n, ACT, generator=g) * torch.tensor(high - low) + torch.tensor(low),
        Columns.REWARDS: torch.randn(n, generator=g), COSTS: torch.rand(n, generator=g),
        Columns.TERMINATEDS: torch.arange(n) % 5 == 0, Columns.TRUNCATEDS: torch.arange(n) % 7 == 0,
    }


class _Cfg:
    alpha, gamma, cost_gamma = 0.2, 0.9, 0.8


def test_cost_target_takes_the_deterministic_next_action_and_one_cost_critic():
    module, batch = _module(), _batch()
    assert module.reward_critics.n_members == 2 and module.cost_critic.n_members == 1
    torch.manual_seed(1)
    fwd = module.forward_train(batch)
    _, y_c = critic_targets(batch, fwd, _Cfg)
    s2 = batch[Columns.NEXT_OBS]
    with torch.no_grad():
        mu = module.actor(s2)[0]
        a_det = torch.tensor(LOW) + (torch.tanh(mu) + 1) / 2 * torch.tensor(HIGH - LOW)
        q_c = module.target_cost_critic(s2, a_det)[0]
        q_c_sampled = module.target_cost_critic(s2, module.sample_action(s2)[0])[0]
    not_done = 1.0 - batch[Columns.TERMINATEDS].float()  # truncation bootstraps
    torch.testing.assert_close(y_c, batch[COSTS] + 0.8 * not_done * q_c)
    assert not torch.allclose(q_c, q_c_sampled, atol=1e-3), "the test must tell the two next actions apart"
    torch.testing.assert_close(module.deterministic_action(s2), a_det)


def test_the_targets_run_the_actor_once_on_the_next_observations():
    """a' ~ π(·|s') and the cost target's squash(μ(s')) come from one actor forward (one is the
    other's mean): the critic step's targets cost one actor pass, not two."""
    module, batch = _module(), _batch()
    seen = []
    hook = module.actor.register_forward_hook(lambda mod, args, out: seen.append(args[0]))
    try:
        module.forward_train(batch)
    finally:
        hook.remove()
    assert len(seen) == 1 and torch.equal(seen[0], batch[Columns.NEXT_OBS])


def test_critic_dtype_auto_resolves_where_the_module_is_built(monkeypatch):
    from lac_rllib.constrained import precision

    wide = (BF16_MIN_WIDTH, BF16_MIN_WIDTH)
    for flags, expected in (({"avx2", "avx512_bf16"}, torch.bfloat16), ({"avx2"}, torch.float32)):
        monkeypatch.setattr(precision, "cpu_flags", lambda flags=flags: flags)
        module = _module(critic_dtype="auto", critic_hidden=wide)
        critics = (module.reward_critics, module.cost_critic, module.target_reward_critics, module.target_cost_critic)
        assert {c.matmul_dtype for c in critics} == {expected}
        assert SACLagConfig().training(critic_dtype="auto").resolved() == {"critic_dtype": str(expected)[6:]}
    # Narrower critics stay float32 under auto even where bf16 is native (the casts would cost more).
    monkeypatch.setattr(precision, "cpu_flags", lambda: {"avx2", "avx512_bf16"})
    narrow = (BF16_MIN_WIDTH, BF16_MIN_WIDTH // 2)
    assert _module(critic_dtype="auto", critic_hidden=narrow).reward_critics.matmul_dtype == torch.float32
    config = SACLagConfig().training(critic_dtype="auto", critic_hidden=narrow)
    assert config.resolved() == {"critic_dtype": "float32"}
    assert _module().reward_critics.matmul_dtype == torch.float32  # the default: OmniSafe's float32
    assert _module(critic_dtype="bfloat16").cost_critic.matmul_dtype == torch.bfloat16
    with pytest.raises(ValueError, match="critic_dtype.*float16.*accepted.*float32.*bfloat16.*auto"):
        SACLagConfig().training(critic_dtype="float16")


def test_reward_target_is_the_soft_min_over_the_twin_targets():
    module, batch = _module(), _batch()
    torch.manual_seed(2)
    fwd = module.forward_train(batch)
    y_r, _ = critic_targets(batch, fwd, _Cfg)
    torch.manual_seed(2)  # the same draw of a' ~ π(·|s'): the forward's first random numbers
    s2 = batch[Columns.NEXT_OBS]
    with torch.no_grad():
        a2, logp2 = module.sample_action(s2)
        q1, q2 = module.target_reward_critics(s2, a2)
    assert ((q1 < q2).any() and (q2 < q1).any()), "both critics must be the minimum somewhere"
    not_done = 1.0 - batch[Columns.TERMINATEDS].float()
    torch.testing.assert_close(y_r, batch[Columns.REWARDS] + 0.9 * not_done * (torch.minimum(q1, q2) - 0.2 * logp2))
    # log π is the density of RLlib's squashed Gaussian, the one the env runners sample from.
    mean, log_std = module.actor(s2)
    dist = module.action_dist_cls.from_logits(torch.cat([mean, log_std], -1))
    torch.testing.assert_close(dist.logp(a2), logp2, atol=2e-3, rtol=1e-4)


def test_actor_backward_leaves_the_critic_gradients_untouched():
    module, batch = _module(), _batch()
    loss = actor_loss(module.forward_actor(batch[Columns.OBS]), torch.tensor(0.7), alpha=0.2)
    loss.backward()
    critics = [*module.reward_critics.parameters(), *module.cost_critic.parameters()]
    assert all(p.grad is None for p in critics)
    assert all(p.requires_grad for p in critics)  # frozen for the actor's forward only
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in module.actor.parameters())


def test_raising_the_multiplier_raises_the_actor_losss_weight_on_the_cost_critic():
    n, alpha = 8, 0.2
    q_r = torch.randn(2, n, requires_grad=True)
    q_c, logp = torch.randn(n, requires_grad=True), torch.randn(n, requires_grad=True)
    weights = []
    for nu in (0.0, 0.5, 2.0, 10.0):
        out = {M.LOGP: logp, M.Q_REWARD_PI: q_r, M.Q_COST_PI: q_c}
        d_qc, d_qr, d_logp = torch.autograd.grad(actor_loss(out, torch.tensor(nu), alpha), [q_c, q_r, logp])
        # L = mean(α·logπ − min Q_R + ν·Q_C) / (1 + ν)
        torch.testing.assert_close(d_qc, torch.full((n,), nu / (1 + nu) / n))
        torch.testing.assert_close(d_logp, torch.full((n,), alpha / (1 + nu) / n))
        picked = (q_r == q_r.min(0).values).float()
        torch.testing.assert_close(d_qr, -picked / (1 + nu) / n)
        weights.append(float(d_qc[0]))
    assert weights == sorted(weights) and weights[0] == 0.0 < weights[-1]


def _learner(**sets):
    config = SACLagConfig.build("lac/PointHazard-v0", 0, {"actor_hidden": (16, 16), "critic_hidden": (16, 16), **sets})
    return config.build_learner(env=get_task("lac/PointHazard-v0").make({}))


def _update(learner, steps, lifetime=10**6, costs=(3.0,)):
    # A PointHazard-shaped batch (7 observations, actions in [−1, 1]).
    b = {k: v.numpy() for k, v in _batch(n=256, obs_dim=7, low=-np.ones(ACT), high=np.ones(ACT)).items()}
    learner.update(batch=MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(b)}, env_steps=256), minibatch_size=64,
                   num_total_minibatches=steps, num_epochs=2, shuffle_batch_per_epoch=True,
                   timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: lifetime, TS_EPISODE_COSTS: list(costs)})


def _snapshot(net):
    return [p.detach().clone() for p in net.parameters()]


def _moved(before, net):
    return any(not torch.equal(a, b) for a, b in zip(before, net.parameters()))


def test_policy_delay_steps_the_actor_and_polyak_on_every_second_update_only(one_torch_thread):
    learner = _learner(policy_delay=2)
    module = learner.module[DEFAULT_MODULE_ID]
    actor_adam = learner.get_optimizer(DEFAULT_MODULE_ID, ACTOR)
    seen = []
    for _ in range(4):
        actor, critics = _snapshot(module.actor), _snapshot(module.reward_critics)
        targets = _snapshot(module.target_reward_critics), _snapshot(module.target_cost_critic)
        _update(learner, 1)
        targets_moved = _moved(targets[0], module.target_reward_critics), _moved(targets[1], module.target_cost_critic)
        assert targets_moved[0] == targets_moved[1]
        seen.append((_moved(actor, module.actor), targets_moved[0], _moved(critics, module.reward_critics)))
        if len(seen) == 1:  # off its step the actor's Adam is not stepped at all: no moments yet
            assert all(len(actor_adam.state.get(p, {})) == 0 for g in actor_adam.param_groups for p in g["params"])
    assert seen == [(False, False, True), (True, True, True)] * 2
    assert learner.updates == 4


def test_a_nan_gradient_is_zeroed_as_torch_learner_does(one_torch_thread):
    """SAC-Lag's steps go through TorchLearner's apply_gradients, whose guard turns NaN/inf gradients
    into zeros instead of writing NaN into the weights (and Polyak then into the targets): a NaN
    observation makes every network's gradient NaN, the critics' and the actor's own step's."""
    learner = _learner(policy_delay=1)  # every update steps the actor and Polyak too
    module = learner.module[DEFAULT_MODULE_ID]
    b = {k: v.numpy() for k, v in _batch(n=64, obs_dim=7, low=-np.ones(ACT), high=np.ones(ACT)).items()}
    b[Columns.OBS][3, 0] = np.nan
    learner.update(batch=MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(b)}, env_steps=64), minibatch_size=64,
                   num_total_minibatches=1, num_epochs=1, shuffle_batch_per_epoch=False,
                   timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 10**6, TS_EPISODE_COSTS: [3.0]})
    nets = (module.reward_critics, module.cost_critic, module.actor, module.target_reward_critics,
            module.target_cost_critic)
    assert all(torch.isfinite(p).all() for net in nets for p in net.parameters())
    actor_adam = learner.get_optimizer(DEFAULT_MODULE_ID, ACTOR)
    assert all(int(actor_adam.state[p]["step"]) == 1 for p in module.actor.parameters())  # it did step


def test_the_actor_steps_on_the_critics_after_their_step(one_torch_thread):
    """OmniSafe's order (ddpg.py ``_update``): the critics step, then the actor's loss is taken on
    the stepped critics. Checked by hand on one minibatch: the critics the actor's forward sees
    are the updated ones; the loss the learner logs is the hand-computed loss on them (not on the
    critics before their step), and its clipped gradient is what the actor's Adam holds."""
    import copy

    learner = _learner(policy_delay=1)
    module = learner.module[DEFAULT_MODULE_ID]
    before = copy.deepcopy(module)
    seen, forward_actor = {}, module.forward_actor

    def recording(obs):
        seen["obs"], seen["critics"] = obs.clone(), _snapshot(module.reward_critics) + _snapshot(module.cost_critic)
        torch.manual_seed(7)  # the reparameterisation noise, drawn again by hand below
        return forward_actor(obs)

    module.forward_actor = recording
    _update(learner, 1)
    stepped = _snapshot(module.reward_critics) + _snapshot(module.cost_critic)
    old = _snapshot(before.reward_critics) + _snapshot(before.cost_critic)
    assert all(torch.equal(a, b) for a, b in zip(seen["critics"], stepped))
    assert not all(torch.equal(a, b) for a, b in zip(seen["critics"], old))

    def by_hand(critics_of):
        hand = copy.deepcopy(before)  # the actor and ν before the update
        hand.reward_critics.load_state_dict(critics_of.reward_critics.state_dict())
        hand.cost_critic.load_state_dict(critics_of.cost_critic.state_dict())
        torch.manual_seed(7)
        return actor_loss(hand.forward_actor(seen["obs"]), hand.nu, learner.config.alpha), hand

    on_stepped, hand = by_hand(module)
    on_old, _ = by_hand(before)
    logged = float(learner._last[DEFAULT_MODULE_ID][ACTOR_LOSS])
    assert logged == pytest.approx(float(on_stepped), abs=1e-6)
    assert abs(float(on_old) - float(on_stepped)) > 1e-4  # the two orders are told apart
    grads = torch.autograd.grad(on_stepped, list(hand.actor.parameters()))
    scale = min(1.0, learner.config.max_grad_norm / (float(torch.nn.utils.get_total_norm(grads)) + 1e-6))
    adam = learner.get_optimizer(DEFAULT_MODULE_ID, ACTOR)
    for p, g in zip(module.actor.parameters(), grads):  # Adam's first moment after one step: (1 − β₁)·g
        torch.testing.assert_close(adam.state[p]["exp_avg"], 0.1 * scale * g, atol=1e-7, rtol=1e-5)


def test_lambda_waits_for_the_warm_up_then_steps_once_per_update(one_torch_thread):
    learner = _learner(warmup_env_steps=1000, lagrangian_lr=0.01, nu_init=0.0, cost_limit=2.0)
    nu = learner.module[DEFAULT_MODULE_ID].nu
    _update(learner, 3, lifetime=1000, costs=[5.0])
    assert float(nu) == 0.0  # not past the warm-up
    _update(learner, 3, lifetime=1001, costs=[])
    # Ĵ_C = 5 > b: Adam's first steps move λ by ~lr each (|m̂/√v̂| = 1 for a constant gradient).
    assert float(nu) == pytest.approx(0.03, rel=1e-4)
    assert list(learner.cost_window) == [5.0] and learner.episode_cost == 5.0


def _probe_config(**sets):
    base = {"obs_normalization": False, "env_steps_per_iteration": 50, "replay_capacity": 1000, "batch_size": 16,
            "actor_hidden": (16, 16), "critic_hidden": (16, 16), "random_env_steps": 50, "num_envs_per_env_runner": 1}
    return SACLagConfig.build(PROBE, 0, {**base, **sets})


@pytest.mark.parametrize("num_envs, draws", [(1, "with_replacement"), (3, "with_replacement"), (3, "shuffled_passes")])
def test_every_train_row_carries_its_own_cost(ray_session, num_envs, draws):
    # 50 steps per iteration with 7-step episodes: chunks are cut mid-episode every time. Drawn
    # with replacement, the batch is the iteration's 50 minibatches of 16 rows; else the buffer.
    algo = _probe_config(num_envs_per_env_runner=num_envs, minibatch_draws=draws).build_algo()
    try:
        for _ in range(3):
            result = algo.train()
        b = train_batch(algo)
        t = b[Columns.OBS][:, 0]
        assert result[ENV_STEPS] >= 150
        assert len(t) == (50 * 16 if draws == "with_replacement" else result[ENV_STEPS])
        np.testing.assert_array_equal(b[COSTS], 2 * t + 1)
        np.testing.assert_array_equal(b[Columns.REWARDS], -t)
        np.testing.assert_array_equal(b[Columns.NEXT_OBS][:, 0], t + 1)
        np.testing.assert_array_equal(b[Columns.TERMINATEDS], t == 6)
        assert result[EPISODE_COST] == 49.0  # Σ_{t<7} (2t+1), across chunk boundaries
        # The learner's window holds the completed episodes' costs the algorithm handed it.
        window = algo.learner_group._learner.cost_window
        assert len(window) == 10 and set(window) == {49.0}
    finally:
        algo.stop()


def test_checkpoint_restores_lambda_its_adam_state_and_the_cost_window(ray_session, tmp_path):
    algo = _probe_config(cost_limit=40.0, warmup_env_steps=0, lagrangian_lr=0.01, nu_init=0.1,
                         cost_window=3).build_algo()
    try:
        results = [algo.train() for _ in range(2)]
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        learner = algo.learner_group._learner
        before = (float(learner.module[DEFAULT_MODULE_ID].nu), learner.multipliers[DEFAULT_MODULE_ID].get_state(),
                  list(learner.cost_window), learner.updates)
        weights = {k: v.clone() for k, v in learner.module[DEFAULT_MODULE_ID].state_dict().items()}
        next_nu = learner.multipliers[DEFAULT_MODULE_ID].step(learner.episode_cost)  # the step a resume takes
    finally:
        algo.stop()
    assert results[-1][NU] == before[0] > 0.1, "λ must have moved for the round trip to mean anything"
    assert before[1]["rule"]["t"] == before[3] > 0  # one Adam step of λ per gradient step

    restored = SACLag.from_checkpoint(path)
    try:
        learner = restored.learner_group._learner
        after = (float(learner.module[DEFAULT_MODULE_ID].nu), learner.multipliers[DEFAULT_MODULE_ID].get_state(),
                 list(learner.cost_window), learner.updates)
        assert after == before
        for k, v in learner.module[DEFAULT_MODULE_ID].state_dict().items():
            torch.testing.assert_close(v, weights[k], rtol=0, atol=0)
        assert learner.multipliers[DEFAULT_MODULE_ID].step(learner.episode_cost) == next_nu
        assert float(learner.module[DEFAULT_MODULE_ID].nu) == next_nu  # the module's buffer is λ
        restored.train()
    finally:
        restored.stop()


def test_env_runners_act_with_the_actor_on_its_bounds():
    module = _module()
    obs = torch.randn(2000, OBS)
    with torch.no_grad():
        inputs = module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
    dist = module.get_exploration_action_dist_cls().from_logits(inputs)
    samples = dist.sample()
    assert (samples >= torch.tensor(LOW)).all() and (samples <= torch.tensor(HIGH)).all()
    torch.testing.assert_close(dist.to_deterministic().sample(), module.deterministic_action(obs))
    # log σ as the module clamped it, not clamped again to RLlib's [−5, 2]: a σ of e^−10 stays e^−10
    # (at μ = 0 the spread of the actions is σ·(high − low)/2).
    tight = module.action_dist_cls.from_logits(torch.cat([torch.zeros(4000, ACT), torch.full((4000, ACT), -10.0)], -1))
    spread = tight.sample().std(0) / torch.tensor((HIGH - LOW) / 2)
    torch.testing.assert_close(spread, torch.full((ACT,), float(np.exp(-10.0))), rtol=0.1, atol=0)


def test_the_registry_interface():
    mod = registry.algo_config("sac_lag")
    assert mod is SACLagConfig and SACLagConfig.FIELDS is FIELDS and SACLagConfig.PRESETS is PRESETS
    assert set(PRESETS) == {"mujoco", "safety_gym", "tiny"} and mod.ACTIONS == ("generator", "stochastic")
    assert mod.SPEED_FIELDS <= FIELDS.names and "torch_threads" in mod.SPEED_FIELDS
    nav = registry.build_config("sac_lag", "SafetyPointGoal1-v0", 0, {}, timesteps=1000)
    assert (nav.alpha, nav.actor_lr, nav.critic_lr, nav.nu_init, nav.lagrangian_lr) == (1e-5, 5e-6, 1e-3, 0.0, 5e-7)
    assert nav.obs_normalization is False and nav.effective_cost_limit == 25.0
    assert registry.parse_sets("sac_lag", ["alpha=0.05", "actor_hidden=(8, 8)"]) == {"alpha": 0.05,
                                                                                     "actor_hidden": (8, 8)}
    with pytest.raises(ValueError, match=r"SAC-Lag config field lagrangian_rule='pid' is invalid; accepted: adam"):
        SACLagConfig().training(lagrangian_rule="pid")
    with pytest.raises(ValueError, match="log_std_min < log_std_max"):
        SACLagConfig.build("lac/PointHazard-v0", 0, {"log_std_min": 2.0})
    docs = FIELDS.docs()
    assert set(docs) == FIELDS.names and all(docs.values())
