"""TRPO-Lag: its defaults and δ's units, and its learner's step on a real batch (RLlib's own env
runner sampling lac/PointHazard-v0 with the learner's policy, in this process: no Ray): the accepted
step keeps KL ≤ δ and improves the surrogate, measured here with torch's own Normal; a rejected one
leaves the policy bit for bit; Adam steps the critics only."""

import copy

import pytest
import torch
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms.trpo_lag import config as C
from lac_rllib.constrained.costs import completed_episode_stats
from lac_rllib.constrained.metrics import KL_FULL_BATCH, NU, TS_EPISODE_COSTS
from lac_rllib.families.trust_region import learner as L
from lac_rllib.families.trust_region.config import LINE_SEARCH_BACKTRACKS, LINE_SEARCH_FRACTION
from lac_rllib.families.trust_region.step import flat_params
from lac_rllib.tasks import get_task

TASK = "lac/PointHazard-v0"  # obs (7,), action (2,): δ on RLlib's summed KL is 2·target_kl
ROWS = 400


def test_defaults_are_omnisafes_and_delta_is_per_action_dimension():
    config = C.TRPOLagConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert (config.target_kl, config.kl_per_action_dim, config.cg_iters, config.cg_damping, config.backtrack_iters,
            config.backtrack_coeff) == (0.01, True, 15, 0.1, 15, 0.8)  # TRPOLag.yaml, trpo.py
    assert (config.critic_lr, config.num_epochs, config.minibatch_size, config.nu_init, config.lagrangian_lr,
            config.train_batch_size_per_learner) == (1e-3, 10, 128, 0.001, 0.035, 20_000)
    assert config.max_kl(2) == pytest.approx(0.02) and config.max_kl(17) == pytest.approx(0.17)
    ssa = C.TRPOLagConfig.build("SafetyPointGoal1-v0", 0, {"preset": "ssa"}, timesteps=100_000)
    assert (ssa.cg_iters, ssa.backtrack_iters, ssa.backtrack_coeff, ssa.nu_init, ssa.lagrangian_lr,
            ssa.nu_parametrization, ssa.train_batch_size_per_learner, ssa.hidden, ssa.minibatch_size) == \
        (10, 10, 0.8, 1.0, 0.05, "softplus", 30_000, (256, 256), None)
    assert ssa.max_kl(2) == 0.01  # [S]'s KL sums over the dimensions: δ is not converted
    docs = C.TRPOLagConfig.FIELDS.docs()
    assert set(docs) == C.TRPOLagConfig.FIELDS.names and all(docs.values()) and set(C.PRESETS) == set(C.PRESET_NAMES)


def learner_and_episodes(**fields):
    """A TRPO-Lag Learner built in this process and ROWS env steps its own policy sampled (RLlib's
    env runner, seeded: the same episodes every run)."""
    config = C.TRPOLagConfig().task(TASK).training(
        total_env_steps=10_000, train_batch_size_per_learner=ROWS, num_envs_per_env_runner=1, minibatch_size=100,
        num_epochs=2, **fields).debugging(seed=0)
    lrn = config.build_learner(env=get_task(TASK).make())
    runner = SingleAgentEnvRunner(config=config, worker_index=0)
    runner.set_state({COMPONENT_RL_MODULE: {DEFAULT_MODULE_ID: lrn.module[DEFAULT_MODULE_ID].get_state(
        inference_only=True)}})
    return lrn, runner.sample(num_timesteps=ROWS, random_actions=False)


def update(lrn, episodes) -> dict:
    costs = completed_episode_stats(episodes)[1]
    results = lrn.update(episodes=episodes, timesteps={TS_EPISODE_COSTS: costs}, minibatch_size=100, num_epochs=2)
    return {k: float(v.peek()) for k, v in results[DEFAULT_MODULE_ID].items() if not isinstance(v, dict)}


def normal(module, obs):
    mean, log_std = module.action_dist_inputs(obs).chunk(2, dim=-1)
    return torch.distributions.Normal(mean, log_std.exp())


def policy_state(module) -> dict:
    return {k: v.clone() for k, v in module.state_dict().items() if k.startswith(("encoder.actor_encoder", "pi."))}


def critic_state(module) -> dict:
    return {k: v.detach().clone() for k, v in module.named_parameters()
            if k.startswith(("encoder.critic_encoder", "vf.", "cost_vf."))}


def test_unconstrained_trpo_steps_inside_the_trust_region_and_improves_the_surrogate(monkeypatch):
    """ν pinned at 0 (lagrangian_lr 0, nu_init 0): the step on A^R. Measured on the whole batch's
    real rows with torch.distributions.Normal: mean KL(π_old ‖ π_new), summed over the 2 action
    dimensions, ≤ δ = 2·0.01, and mean r·A^R rose. The policy is then θ_old + fraction·Δθ bit for
    bit although the critics took 2 epochs of Adam steps after it."""
    lrn, episodes = learner_and_episodes(target_kl=0.01, lagrangian_lr=0.0, nu_init=0.0)
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    old = copy.deepcopy(module)
    steps, search = [], L.line_search
    monkeypatch.setattr(L, "line_search", lambda params, step, *a, **k: steps.append(step) or search(params, step,
                                                                                                        *a, **k))
    critics = critic_state(module)
    out = update(lrn, episodes)
    whole = lrn.cost_gae.last_batch[DEFAULT_MODULE_ID]
    real, obs, actions = whole[Columns.LOSS_MASK], whole[Columns.OBS], whole[Columns.ACTIONS]
    with torch.no_grad():
        new_dist, old_dist = normal(module, obs), normal(old, obs)
        kl = torch.distributions.kl_divergence(old_dist, new_dist).sum(-1)[real].mean()

        def surrogate(dist):
            ratio = torch.exp(dist.log_prob(actions).sum(-1) - whole[Columns.ACTION_LOGP])
            return (ratio * whole[Postprocessing.ADVANTAGES])[real].mean()

        gain = surrogate(new_dist) - surrogate(old_dist)
    assert out[NU] == 0.0 and float(module.nu) == 0.0
    assert 0.0 < out[LINE_SEARCH_FRACTION] <= 1.0
    assert 0.0 < float(kl) <= 0.02 and out[KL_FULL_BATCH] == pytest.approx(float(kl), rel=1e-4)
    assert float(gain) > 0.0
    theta_old = flat_params([*old.encoder.actor_encoder.parameters(), *old.pi.parameters()])
    theta = flat_params([*module.encoder.actor_encoder.parameters(), *module.pi.parameters()])
    assert len(steps) == 1 and torch.equal(theta, theta_old + out[LINE_SEARCH_FRACTION] * steps[0])
    assert any(not torch.equal(v, critics[k]) for k, v in critic_state(module).items())


def test_a_rejected_step_leaves_the_policy_bit_for_bit_and_the_critics_step(monkeypatch):
    """Every fraction rejected: θ_old kept bit for bit, fraction 0 after backtrack_iters tries; the
    critics' Adam steps happened; no optimizer holds a policy parameter."""
    monkeypatch.setattr(L, "trpo_acceptance", lambda *args: (lambda fraction: False))
    lrn, episodes = learner_and_episodes(backtrack_iters=4)
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    policy_ids = {id(p) for net in (module.encoder.actor_encoder, module.pi) for p in net.parameters()}
    optimized = {id(p) for _, optim in lrn.get_optimizers_for_module(DEFAULT_MODULE_ID)
                 for group in optim.param_groups for p in group["params"]}
    assert {name for name, _ in lrn.get_optimizers_for_module(DEFAULT_MODULE_ID)} == {"critic", "cost_critic"}
    assert optimized and not optimized & policy_ids
    policy, critics = policy_state(module), critic_state(module)
    out = update(lrn, episodes)
    assert all(torch.equal(v, policy[k]) for k, v in policy_state(module).items())
    assert (out[LINE_SEARCH_FRACTION], out[LINE_SEARCH_BACKTRACKS], out[KL_FULL_BATCH]) == (0.0, 4.0, 0.0)
    assert all(not torch.equal(v, critics[k]) for k, v in critic_state(module).items())
