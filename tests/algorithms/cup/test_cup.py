"""CUP: its defaults, stage 2's loss against a hand computation, what each stage steps (a Learner
built in this process, on both update paths), and two iterations of the algorithm on Ray."""

import math

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.utils.metrics import LEARNER_RESULTS

from lac_rllib.algorithms.cup import config as C
from lac_rllib.algorithms.cup import learner as cup_learner
from lac_rllib.algorithms.cup.row_index import ROW_INDEX
from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.constrained import metrics
from lac_rllib.constrained.metrics import TS_EPISODE_COSTS
from lac_rllib.constrained.minibatch_loop import update_kwargs
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.projection import kl_to_reference
from lac_rllib.tasks import get_task

PROBE = "lac/CostProbe-v0"  # obs (1,), action (1,); the episodes below are built by hand
MID = DEFAULT_MODULE_ID
PATHS = ["rllib", "fused"]


def test_defaults_are_cup_yaml():
    config = C.CUPConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert (config.target_kl, config.nu_max, config.nu_init, config.lagrangian_lr, config.clip_param) == \
        (0.01, 2.0, 0.001, 0.035, 0.2)
    assert (config.num_epochs, config.stage2_epochs, config.minibatch_size) == (40, 40, 64)  # update_iters both
    tiny = C.CUPConfig.build("lac/PointHazard-v0", 0, {"projection_epochs": 3}, timesteps=1000)
    assert (tiny.stage2_epochs, tiny.num_epochs, tiny.target_kl) == (3, 10, 0.02)  # the tiny preset's KL stop
    assert set(C.PRESETS) == set(C.PRESET_NAMES) == {"mujoco", "safety_gym", "tiny", "omnisafe"}
    assert {C.PROJECTION_LOSS, C.PROJECTION_EPOCHS, C.PROJECTION_KL} <= set(C.CUPConfig.REPORTED_KEYS)
    docs = C.CUPConfig.FIELDS.docs()
    assert set(docs) == C.CUPConfig.FIELDS.names and all(docs.values())


# ----- a Learner in this process -----
def learner(config_class=C.CUPConfig, **fields):
    """A learner on the probe's spaces; the policy's lr high enough that a step moves it."""
    fields = {"obs_normalization": False, "total_env_steps": 1000, "lr": 1e-2, "target_kl": None, **fields}
    config = config_class().task(PROBE).training(**fields)
    torch.manual_seed(0)
    return config.build_learner(env=get_task(PROBE).make())


def episode(length, *, seed=0):
    """An episode chunk on the probe: step t costs 2t + 1, with the behaviour policy's outputs."""
    spec, rng = get_task(PROBE), np.random.default_rng(seed)
    env = spec.make()
    dist_inputs = rng.normal(size=(length, 2)).astype(np.float32) * 0.3
    actions = rng.normal(size=(length, 1)).astype(np.float32)
    logp = (-0.5 * ((actions[:, 0] - dist_inputs[:, 0]) / np.exp(dist_inputs[:, 1])) ** 2 - dist_inputs[:, 1]
            - 0.5 * np.log(2 * np.pi)).astype(np.float32)
    return SingleAgentEpisode(
        observations=[np.array([t], np.float32) for t in range(length + 1)],
        infos=[{"cost": 0.0}] + [{"cost": float(2 * t + 1)} for t in range(length)],
        actions=list(actions), rewards=list(rng.normal(size=length)),
        extra_model_outputs={Columns.ACTION_DIST_INPUTS: list(dist_inputs), Columns.ACTION_LOGP: list(logp)},
        len_lookback_buffer=0, observation_space=env.observation_space, action_space=env.action_space,
    ).to_numpy()


def update(lrn, path, *, num_epochs=2, minibatch_size=4):
    """One update call, as the algorithm makes it on ``path`` (shuffled minibatches, seeded)."""
    kwargs = update_kwargs(path, minibatch_size=minibatch_size, num_epochs=num_epochs, shuffle=True)
    np.random.seed(0)
    return lrn.update(episodes=[episode(8), episode(5, seed=1)],
                      timesteps={**kwargs.pop("timesteps"), TS_EPISODE_COSTS: [30.0]}, **kwargs)


def params(module) -> dict:
    """The module's weights (its parameters: ν and RLlib's constants are buffers)."""
    return {k: v.detach().clone() for k, v in module.named_parameters()}


def policy_and_critics(state: dict) -> tuple[dict, dict]:
    policy = {k: v for k, v in state.items() if k.startswith(("pi.", "encoder.actor_encoder."))}
    return policy, {k: v for k, v in state.items() if k not in policy}


@pytest.fixture
def switch(monkeypatch):
    """Records, at stage 2's first minibatch, the module's weights and the minibatch's rows and
    distribution inputs, and every KL term stage 2's loss computes."""
    seen = {"kl": []}
    original_loss, original_kl = cup_learner.CUPTorchLearner.projection_loss, cup_learner.kl_to_reference

    def projection_loss(self, module_id, config, module, batch, fwd_out, reference):
        if "state" not in seen:
            seen.update(state=params(module), rows=batch[ROW_INDEX].clone(),
                        logits=fwd_out[Columns.ACTION_DIST_INPUTS].detach().clone())
        return original_loss(self, module_id, config, module, batch, fwd_out, reference)

    def kl_to_reference(dist_cls, logits, reference_logits):
        kl = original_kl(dist_cls, logits, reference_logits)
        seen["kl"].append(kl.detach().clone())
        return kl

    monkeypatch.setattr(cup_learner.CUPTorchLearner, "projection_loss", projection_loss)
    monkeypatch.setattr(cup_learner, "kl_to_reference", kl_to_reference)
    return seen


def test_stage_two_loss_against_a_hand_computation():
    """ν·(1 − γλ)/(1 − γ)·r·A^C + KL(π_θ ‖ π_stage1), averaged over the real rows, with each
    row's π_stage1 read from the whole-batch snapshot at its ROW_INDEX."""
    lrn = learner(nu_init=0.3)
    module = lrn.module[MID].unwrapped()
    rng = np.random.default_rng(3)
    obs = torch.tensor(rng.normal(size=(4, 1)), dtype=torch.float32)
    batch = {Columns.OBS: obs, Columns.ACTIONS: torch.tensor(rng.normal(size=(4, 1)), dtype=torch.float32),
             Columns.ACTION_LOGP: torch.tensor(rng.normal(size=4) - 1.0, dtype=torch.float32),
             COST_ADVANTAGES: torch.tensor([1.5, -2.0, 0.7, 9.0], dtype=torch.float32),
             Columns.LOSS_MASK: torch.tensor([True, True, True, False]), ROW_INDEX: torch.tensor([4, 0, 5, 2])}
    reference = torch.tensor(rng.normal(size=(6, 2)) * 0.5, dtype=torch.float32)  # [mean, log σ] per batch row
    with torch.no_grad():
        logits = module.action_dist_inputs(obs)
        loss = lrn.projection_loss(MID, lrn.config, module, batch, {Columns.ACTION_DIST_INPUTS: logits}, reference)

    f64 = {k: v.double().numpy() for k, v in batch.items()}
    mu, log_std = logits.double().numpy().T
    ref_mu, ref_log_std = reference.double().numpy()[batch[ROW_INDEX].numpy()].T
    a = f64[Columns.ACTIONS][:, 0]
    logp = -0.5 * ((a - mu) / np.exp(log_std)) ** 2 - log_std - 0.5 * np.log(2 * np.pi)
    ratio = np.exp(logp - f64[Columns.ACTION_LOGP])
    kl = ref_log_std - log_std + (np.exp(2 * log_std) + (mu - ref_mu) ** 2) / (2 * np.exp(2 * ref_log_std)) - 0.5
    coef = (1 - 0.99 * 0.95) / (1 - 0.99)  # γ, λ: OmniSafe's gamma and lam
    per_row = 0.3 * coef * ratio * f64[COST_ADVANTAGES] + kl
    assert float(loss) == pytest.approx(per_row[:3].mean(), rel=1e-6, abs=1e-6)
    assert abs(per_row[3]) > 1  # the phantom row would have counted


@pytest.mark.parametrize("path", PATHS)
def test_stage_two_kl_is_to_the_stage_one_policy(switch, path):
    lrn = learner(nu_init=1.0, lagrangian_lr=0.0, num_epochs=2, minibatch_size=4, update_path=path)
    update(lrn, path)
    whole = lrn.cost_gae.last_batch[MID]
    dist_cls = lrn.module[MID].unwrapped().get_train_action_dist_cls()
    behaviour = whole[Columns.ACTION_DIST_INPUTS].index_select(0, switch["rows"])
    kl_to_behaviour = kl_to_reference(dist_cls, switch["logits"], behaviour)
    assert float(kl_to_behaviour.max()) > 1e-3  # stage 1 moved the policy away from the behaviour
    first = switch["kl"][0]  # stage 2's first minibatch: the policy still is π_stage1
    assert len(first) == 4 and float(first.abs().max()) < 1e-6
    assert float(switch["kl"][-1].max()) > 1e-6  # and stage 2 moved it


@pytest.mark.parametrize("path", PATHS)
def test_critics_stay_still_in_stage_two(switch, path):
    lrn = learner(nu_init=1.0, lagrangian_lr=0.0, num_epochs=2, minibatch_size=4, update_path=path)
    init_policy, init_critics = policy_and_critics(params(lrn.module[MID]))
    result = update(lrn, path)
    policy, critics = policy_and_critics(switch["state"])
    end_policy, end_critics = policy_and_critics(params(lrn.module[MID]))
    assert all(not torch.equal(init_critics[k], critics[k]) for k in critics)  # stage 1 trained them
    assert all(torch.equal(critics[k], end_critics[k]) for k in critics), "a critic moved in stage 2"
    assert any(not torch.equal(policy[k], end_policy[k]) for k in policy)  # stage 2 trained the policy
    assert result[MID][C.PROJECTION_EPOCHS] == 2  # no KL stop: every epoch of stage 2


@pytest.mark.parametrize("path", PATHS)
def test_nu_does_not_enter_stage_one(switch, path):
    """Stage 1 with ν = 1.5 makes PPO-Lag's update with ν = 0, weight for weight."""
    fields = {"lagrangian_lr": 0.0, "num_epochs": 2, "minibatch_size": 4, "update_path": path}
    cup, ppo = learner(nu_init=1.5, **fields), learner(PPOLagConfig, nu_init=0.0, **fields)
    assert all(torch.equal(v, params(ppo.module[MID])[k]) for k, v in params(cup.module[MID]).items())
    update(cup, path)
    update(ppo, path)
    assert float(cup.module[MID].nu) == 1.5 and float(ppo.module[MID].nu) == 0.0
    stage_one, ppo_lag = switch["state"], params(ppo.module[MID])
    different = [k for k in stage_one if not torch.equal(stage_one[k], ppo_lag[k])]
    assert not different, different


# ----- the algorithm on Ray -----
@pytest.mark.parametrize("minibatch_size", [100, None])  # the fused loop; RLlib's (full-batch epochs)
def test_cup_trains_and_reports_its_keys(ray_session, minibatch_size):
    sets = {"train_batch_size_per_learner": 400, "minibatch_size": minibatch_size, "num_epochs": 2,
            "num_envs_per_env_runner": 4, "hidden": (32, 32)}
    algo = C.CUPConfig.build("lac/PointHazard-v0", 0, sets, timesteps=20_000).build_algo()
    try:
        assert algo.config.ALGO == "cup"
        for _ in range(2):
            result = algo.train()
    finally:
        algo.stop()
    row = metrics.iteration_row(result, C.CUPConfig.REPORTED_KEYS)
    assert set(C.CUPConfig.REPORTED_KEYS) <= set(row), set(C.CUPConfig.REPORTED_KEYS) - set(row)
    assert all(math.isfinite(row[k]) for k in C.CUPConfig.REPORTED_KEYS), row
    assert 1 <= row[C.PROJECTION_EPOCHS] <= 2 and row[C.PROJECTION_KL] >= 0
    assert 0 <= result[LEARNER_RESULTS][MID][metrics.NU] <= 2.0  # nu_max
