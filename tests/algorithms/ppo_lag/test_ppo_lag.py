"""PPO-Lag without Ray: its config and presets, the cost GAE against its closed form, the advantage
the PPO loss gets, ν's step rules and the KL early stop (a Learner built in this process)."""

import copy
import math

import numpy as np
import pytest
import torch
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.algorithms import registry
from lac_rllib.algorithms.ppo_lag import config as C
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.lagrange import AdamStep, LagrangeMultiplier, SoftplusAdamStep
from lac_rllib.constrained.metrics import EPOCHS_TRAINED, NU, TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES, COST_VALUE_TARGETS, cost_gae
from lac_rllib.families.on_policy.learner import COST_CRITIC, CRITIC, POLICY
from lac_rllib.tasks import get_task

PROBE = "lac/CostProbe-v0"  # obs (1,), action (1,); the episodes below are built by hand
GAMMA_C, LAMBDA = 0.9, 0.8


# ----- config -----
def test_defaults_are_omnisafe_and_rllib_defaults_that_break_it_are_overridden():
    config = C.PPOLagConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert config.vf_clip_param == math.inf  # RLlib's 10 clamps the squared error of cost values
    assert (config.lr, config.clip_param, config.lambda_, config.use_kl_loss, config.entropy_coeff) == \
        (3e-4, 0.2, 0.95, False, 0.0)
    assert (config.train_batch_size_per_learner, config.num_epochs, config.minibatch_size, config.target_kl,
            config.grad_clip, config.nu_init, config.lagrangian_lr, config.cost_window) == \
        (20_000, 40, 64, 0.02, 40.0, 0.001, 0.035, 100)
    model = config.model_config
    assert model["vf_share_layers"] is False and model["free_log_std"] is True
    assert (model["fcnet_hiddens"], model["fcnet_activation"], model["head_fcnet_hiddens"]) == ([64, 64], "tanh", [])
    assert config.preset == "safety_gym" and config.num_envs_per_env_runner == 10
    # the policy's lr decays over OmniSafe's 1e7-step benchmark, not over this run's 100k
    assert config.policy_lr_or_schedule() == [[0, 3e-4], [10_000_000, 0.0]]
    tiny = C.PPOLagConfig.build("lac/PointHazard-v0", 0, {}, timesteps=40_000)  # no preset horizon: its own budget
    assert tiny.policy_lr_or_schedule() == [[0, 1e-3], [40_000, 0.0]]


def test_presets_apply_and_explicit_values_win():
    tiny = C.PPOLagConfig.build("lac/PointHazard-v0", 0, {"lr": 5e-4}, timesteps=1000)
    for name, value in C.PRESETS["tiny"].items():
        assert getattr(tiny, name) == (5e-4 if name == "lr" else value), name
    assert tiny.params()["preset"] == "tiny"
    by_task = C.PPOLagConfig().task("SafetyPointGoal1-v0", preset="ssa")
    by_field = C.PPOLagConfig.build("SafetyPointGoal1-v0", 0, {"preset": "ssa"}, timesteps=1000)
    for config in (by_task, by_field):
        assert config.preset == "ssa"
        for name, value in C.PRESETS["ssa"].items():
            assert getattr(config, name) == value, name
    assert set(C.PRESETS) == set(C.PRESET_NAMES)
    with pytest.raises(ValueError, match="unknown preset 'nope'"):
        C.PPOLagConfig().training(preset="nope")
    with pytest.raises(ValueError, match=r"PPO-Lag config field num_epochs=0 is invalid; accepted: an integer >= 1"):
        C.PPOLagConfig().training(num_epochs=0)
    with pytest.raises(ValueError, match="total_env_steps=None is invalid"):
        C.PPOLagConfig.build("lac/PointHazard-v0", 0, {})
    two = C.PPOLagConfig.build("lac/PointHazard-v0", 0, {}, timesteps=1000, cpus=2)  # the tiny preset's 10 envs
    assert (two.num_env_runners, two.num_envs_per_env_runner, two.torch_threads) == (2, 5, 2)


def test_the_registry_interface():
    module = registry.algo_config("ppo_lag")
    assert module is C.PPOLagConfig and module.FIELDS.params_cls is module.PARAMS
    assert set(module.PRESETS) >= {"mujoco", "safety_gym", "tiny"} and module.ACTIONS == ("generator", "stochastic")
    assert module.SPEED_FIELDS <= module.FIELDS.names
    assert registry.parse_sets("ppo_lag", ["lagrangian_lr=0", "hidden=(32, 32)"]) == \
        {"lagrangian_lr": 0, "hidden": (32, 32)}
    docs = module.FIELDS.docs()
    assert set(docs) == module.FIELDS.names and all(docs.values())


# ----- episodes built by hand -----
def episode(length, *, cost=1.0, terminated=False, t_started=0, seed=0):
    """A numpy episode chunk of ``length`` steps on the probe's spaces: step t costs ``cost`` (a number,
    or a function of the global step), with the behaviour policy's outputs PPO's loss reads."""
    spec = get_task(PROBE)
    env = spec.make()
    rng = np.random.default_rng(seed)
    dist_inputs = rng.normal(size=(length, 2)).astype(np.float32) * 0.3
    actions = rng.normal(size=(length, 1)).astype(np.float32)
    logp = (-0.5 * ((actions[:, 0] - dist_inputs[:, 0]) / np.exp(dist_inputs[:, 1])) ** 2 - dist_inputs[:, 1]
            - 0.5 * np.log(2 * np.pi)).astype(np.float32)
    step_cost = cost if callable(cost) else (lambda t: cost)
    return SingleAgentEpisode(
        observations=[np.array([t_started + t], np.float32) for t in range(length + 1)],
        infos=[{"cost": 0.0}] + [{"cost": float(step_cost(t_started + t))} for t in range(length)],
        actions=list(actions), rewards=list(rng.normal(size=length)), terminated=terminated, t_started=t_started,
        extra_model_outputs={Columns.ACTION_DIST_INPUTS: list(dist_inputs), Columns.ACTION_LOGP: list(logp)},
        len_lookback_buffer=0, observation_space=env.observation_space, action_space=env.action_space,
    ).to_numpy()


def learner(**fields):
    """A PPO-Lag Learner on the probe's spaces, built in this process (no Ray)."""
    config = C.PPOLagConfig().task(PROBE).training(obs_normalization=False, total_env_steps=1000, **fields)
    return config.build_learner(env=get_task(PROBE).make())


def train_batch(lrn, episodes) -> dict:
    """The batch the learner's connector builds from ``episodes`` (numpy)."""
    batch = lrn._learner_connector(rl_module=lrn.module, batch={}, episodes=episodes, shared_data={},
                                   metrics=lrn.metrics)[DEFAULT_MODULE_ID]
    return {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in batch.items()}


def closed_form(length, cost, value, *, terminated):
    """GAE of a chunk with a constant cost and a constant V_C = ``value``:
    δ = c + γv − v on every step but the last, δ_last = c + γ·(0 if terminated else v) − v, so
    A_t = δ·(1 − (γλ)^n)/(1 − γλ) + (γλ)^n·δ_last with n = length − 1 − t steps to the last."""
    g = GAMMA_C * LAMBDA
    delta, last = cost + GAMMA_C * value - value, cost + (0.0 if terminated else GAMMA_C * value) - value
    n = length - 1 - np.arange(length)
    return delta * (1 - g**n) / (1 - g) + g**n * last


LAYOUTS = {  # name → chunks as (length, terminated, t_started): one episode ended, truncated, or cut in two
    "terminated": [(9, True, 0)],
    "truncated": [(9, False, 0)],
    "chunked": [(5, False, 0), (4, True, 5)],
}


@pytest.mark.parametrize("layout", LAYOUTS)
def test_cost_gae_equals_the_closed_form(layout):
    cost, value = 2.0, 0.5
    lrn = learner(cost_gamma=GAMMA_C, lambda_=LAMBDA)
    head = [m for m in lrn.module[DEFAULT_MODULE_ID].cost_vf.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():  # V_C ≡ value: the output layer's weights 0, its bias the value
        head.weight.zero_(), head.bias.fill_(value)
    chunks = LAYOUTS[layout]
    b = train_batch(lrn, [episode(n, cost=cost, terminated=term, t_started=t0) for n, term, t0 in chunks])

    # Each chunk's rows, then its phantom row (the connector's AddOneTsToEpisodesAndTruncate).
    real = np.concatenate([[True] * n + [False] for n, _, _ in chunks])
    np.testing.assert_array_equal(b[Columns.LOSS_MASK], real)
    np.testing.assert_array_equal(b[COSTS], np.where(real, cost, 0.0))  # the phantom repeats the last info: 0
    raw = np.concatenate([np.append(closed_form(n, cost, value, terminated=term), 0.0) for n, term, _ in chunks])
    np.testing.assert_allclose(b[COST_VALUE_TARGETS], np.where(real, raw + value, 0.0), rtol=1e-5)
    # The advantages are centred over the real rows, not rescaled [O].
    np.testing.assert_allclose(b[COST_ADVANTAGES], np.where(real, raw - raw[real].mean(), 0.0), rtol=1e-5, atol=1e-6)
    # The reward advantages are standardised over the real rows only.
    a_r = b[Postprocessing.ADVANTAGES]
    assert abs(a_r[real].mean()) < 1e-5 and a_r[real].std() == pytest.approx(1.0, abs=1e-4)
    assert not a_r[~real].any()


def test_cost_gae_ignores_the_phantom_rows_cost():
    mask = np.array([True, True, False])
    a, t = cost_gae(np.array([1.0, 1.0, 7.0]), np.zeros(3, np.float32), np.array([0, 1, 0.0]), np.zeros(3),
                    mask, gamma=GAMMA_C, lambda_=LAMBDA)
    np.testing.assert_allclose(t, [1 + GAMMA_C * LAMBDA, 1.0, 0.0], rtol=1e-6)
    assert a[2] == 0.0


# ----- the PPO loss gets (A_R − ν·A_C)/(1 + ν) -----
@pytest.mark.parametrize("path", ["rllib", "fused"])
def test_the_ppo_loss_gets_the_lagrangian_advantage(monkeypatch, path):
    """On RLlib's path, RLlib's PPO loss receives the Lagrangian advantage as its ADVANTAGES
    column; on the fused path the learner's own loss (fused_loss) is handed it."""
    lrn = learner(lagrangian_lr=0.0, minibatch_size=None, num_epochs=1, update_path=path)  # ν stays where set
    lrn.module[DEFAULT_MODULE_ID].nu.fill_(0.7)
    seen = {}

    def record(level):
        def wrapped(self, *, module_id, config, batch, fwd_out):
            seen[level] = {k: v.detach().clone() for k, v in batch.items() if isinstance(v, torch.Tensor)}
            return original[level](self, module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)
        return wrapped

    def record_fused(self, module_id, config, module, batch, fwd_out, advantages):
        seen["ppo"] = {Postprocessing.ADVANTAGES: advantages.detach().clone()}
        return original["fused"](self, module_id, config, module, batch, fwd_out, advantages)

    ours = type(lrn)
    original = {"ours": ours.compute_loss_for_module, "ppo": PPOTorchLearner.compute_loss_for_module,
                "fused": ours.fused_loss}
    monkeypatch.setattr(ours, "compute_loss_for_module", record("ours"))
    monkeypatch.setattr(PPOTorchLearner, "compute_loss_for_module", record("ppo"))
    monkeypatch.setattr(ours, "fused_loss", record_fused)
    result = lrn.update(episodes=[episode(8, cost=lambda t: 2 * t + 1), episode(5, cost=1.0, seed=1)],
                        timesteps={TS_EPISODE_COSTS: [30.0]}, num_epochs=1, minibatch_size=None)

    assert float(lrn.module[DEFAULT_MODULE_ID].nu) == pytest.approx(0.7)
    assert float(result[DEFAULT_MODULE_ID][NU]) == pytest.approx(0.7)  # logged for SafeAlgorithm.log_top_level
    inner, outer = seen["ours"], seen["ppo"]
    a_r, a_c = inner[Postprocessing.ADVANTAGES], inner[COST_ADVANTAGES]
    assert a_c.abs().max() > 1, "the test needs cost advantages that matter"
    torch.testing.assert_close(outer[Postprocessing.ADVANTAGES], (a_r - 0.7 * a_c) / 1.7)
    mask = inner[Columns.LOSS_MASK]
    assert abs(float(a_c[mask].mean())) < 1e-4 and float(a_c[mask].std()) > 1.5  # centred, not standardised


# ----- ν's step rules -----
def test_adam_with_lr_zero_pins_nu():
    nu = torch.tensor(0.0)
    multiplier = LagrangeMultiplier(nu, cost_limit=2.0, rule=AdamStep(0.0), bounded=False)
    for cost in (50.0, 0.0, 7.0):
        multiplier.step(cost)
    assert float(nu) == 0.0


def test_softplus_step_is_adam_on_the_inverse_softplus_of_nu():
    """[S]: p = softplus⁻¹(1), Adam (torch's) on the loss −p·(Ĵ_C − b), ν = softplus(p)."""
    p = torch.nn.Parameter(torch.tensor(math.log(math.e - 1)))
    adam = torch.optim.Adam([p], lr=0.05)
    rule, nu = SoftplusAdamStep(0.05, nu_init=1.0), torch.tensor(1.0)
    multiplier = LagrangeMultiplier(nu, cost_limit=25.0, rule=rule, bounded=False)
    for cost in np.random.default_rng(0).uniform(0, 60, size=30):
        adam.zero_grad()
        (-p * (float(cost) - 25.0)).backward()
        adam.step()
        multiplier.step(float(cost))
        assert float(nu) == pytest.approx(float(torch.nn.functional.softplus(p.detach())), rel=1e-5, abs=1e-7)


def test_nu_steps_on_the_window_of_episode_costs():
    lrn = learner(lagrangian_lr=0.035, nu_init=0.0, cost_window=3, cost_limit=2.0)
    lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [40.0, 50.0]})
    assert float(lrn.module[DEFAULT_MODULE_ID].nu) == pytest.approx(0.035)  # Adam's first step is lr·sign
    lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [1.0, 2.0]})
    assert list(lrn.cost_windows[DEFAULT_MODULE_ID]) == [50.0, 1.0, 2.0]
    lrn.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: []})  # none completed: the window stays
    assert list(lrn.cost_windows[DEFAULT_MODULE_ID]) == [50.0, 1.0, 2.0]


# ----- the KL early stop -----
def _params(lrn, name):
    optim = lrn.get_optimizer(DEFAULT_MODULE_ID, name)
    return [p.detach().clone() for group in optim.param_groups for p in group["params"]]


@pytest.mark.parametrize("kl_stop_critics, late", [(True, False), (False, False), (False, True)])
def test_the_kl_stop_ends_the_policy_steps(kl_stop_critics, late):
    """A target KL no step stays under: the policy trains one epoch (one full-batch step) [O], or two
    with ``kl_stop_late`` [S], whatever num_epochs says; the critics stop with it or run on."""
    trained = 2 if late else 1
    lrn = learner(target_kl=1e-12, kl_stop_critics=kl_stop_critics, kl_stop_late=late, minibatch_size=None,
                  lagrangian_lr=0.0)
    start = copy.deepcopy(lrn.get_state())

    def train(epochs):
        lrn.set_state(copy.deepcopy(start))
        result = lrn.update(episodes=[episode(8, cost=1.0), episode(6, cost=3.0, seed=1)], timesteps={},
                            num_epochs=epochs, minibatch_size=None)
        return {n: _params(lrn, n) for n in (POLICY, CRITIC, COST_CRITIC)}, result[DEFAULT_MODULE_ID]

    lrn.set_state(copy.deepcopy(start))
    initial = _params(lrn, POLICY)
    one, _ = train(trained)
    five, result = train(5)
    assert float(result[EPOCHS_TRAINED]) == trained
    assert not all(torch.equal(a, b) for a, b in zip(initial, one[POLICY])), "the first epoch must step the policy"
    same = {name: all(torch.equal(a, b) for a, b in zip(one[name], five[name])) for name in one}
    assert same == {POLICY: True, CRITIC: kl_stop_critics, COST_CRITIC: kl_stop_critics}


# ----- the module -----
def test_deterministic_action_is_the_mean_on_the_action_bounds():
    """With RLlib's normalize_actions the policy acts in [-1, 1] and the env gets that mapped onto
    its bounds, clipped (e.g. the humanoid's Box(−0.4, 0.4)); ν₀ and log σ₀ come from the fields."""
    import gymnasium as gym
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    config = C.PPOLagConfig().training(nu_init=0.3, log_std_init=-0.5)
    space = gym.spaces.Box(-0.4, 0.4, shape=(2,), dtype=np.float32)
    module = RLModuleSpec(module_class=config.get_default_rl_module_spec().module_class,
                          observation_space=gym.spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float32),
                          action_space=space, model_config=config.model_config).build()
    assert float(module.nu) == pytest.approx(0.3)
    torch.testing.assert_close(module.pi.log_std.detach(), torch.full((2,), -0.5))
    obs = torch.randn(64, 3) * 30  # large inputs: some means beyond ±1
    with torch.no_grad():
        mean = module.action_dist_inputs(obs)[:, :2]
    torch.testing.assert_close(module.deterministic_action(obs), (0.4 * mean).clamp(-0.4, 0.4))
