"""PPO-Lag inside RLlib: cost alignment in the train batch, the top-level results, checkpoints."""

import json
import os

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.rl_module import RLModule

from lac_rllib.algorithms.ppo_lag.algorithm import PPOLag
from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import (
    COST_LIMIT,
    ENV_STEPS,
    EPISODE_COST,
    EPISODE_RETURN,
    FEASIBLE,
    NU,
    TS_EPISODE_COSTS,
)
from lac_rllib.families.on_policy.learner import COST_CRITIC, CRITIC, POLICY

PROBE = "lac/CostProbe-v0"  # cost of step t = 2t + 1, obs = t, reward = −t, 7-step episodes


def config(task="lac/PointHazard-v0", seed=0, **fields):
    return PPOLagConfig().task(task).training(total_env_steps=10_000, **fields).debugging(seed=seed)


@pytest.mark.parametrize("num_envs", [1, 3])
def test_every_train_row_carries_its_own_cost(ray_session, monkeypatch, num_envs):
    # 50 steps per iteration with 7-step episodes: chunks are cut mid-episode every time; with a
    # vector env, episodes run side by side and each autoresets on its own.
    seen = []
    original = PPOLagTorchLearner.compute_loss_for_module

    def record(self, *, module_id, config, batch, fwd_out):
        seen.append({k: v.detach().numpy().copy() for k, v in batch.items() if isinstance(v, torch.Tensor)})
        return original(self, module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)

    monkeypatch.setattr(PPOLagTorchLearner, "compute_loss_for_module", record)
    algo = config(PROBE, obs_normalization=False, train_batch_size_per_learner=50, minibatch_size=None,
                  num_epochs=1, num_envs_per_env_runner=num_envs).build_algo()
    try:
        for _ in range(3):
            result = algo.train()
    finally:
        algo.stop()
    assert len(seen) == 3  # one full-batch step per iteration
    steps = num_envs * -(-50 // num_envs)  # RLlib rounds the 50 steps up to whole fragments per env
    for b in seen:
        real, t = b[Columns.LOSS_MASK], b[Columns.OBS][:, 0]
        assert real.sum() == steps and (~real).sum() >= num_envs  # one phantom row per chunk
        np.testing.assert_array_equal(b[COSTS][real], 2 * t[real] + 1)
        np.testing.assert_array_equal(b[Columns.REWARDS][real], -t[real])
        np.testing.assert_array_equal(b[Columns.TERMINATEDS][real], t[real] == 6)
        assert not b[COSTS][~real].any(), "the phantom row repeats the last info; its cost must be 0"
    # Episode totals cross chunk boundaries: Σ_{t<7} (2t+1) = 49, Σ −t = −21.
    assert result[EPISODE_COST] == 49.0 and result[EPISODE_RETURN] == -21.0
    assert {COST_LIMIT, FEASIBLE, NU, ENV_STEPS} <= result.keys() and result[ENV_STEPS] == 3 * steps


def _flat(tree, prefix=""):
    if isinstance(tree, dict):
        return {k2: v2 for k, v in tree.items() for k2, v2 in _flat(v, f"{prefix}/{k}").items()}
    if isinstance(tree, (list, tuple)) and tree and not np.isscalar(tree[0]):
        return {k2: v2 for i, v in enumerate(tree) for k2, v2 in _flat(v, f"{prefix}/{i}").items()}
    return {prefix: tree}


def test_checkpoint_round_trip_keeps_nu_its_adam_state_and_the_cost_window(ray_session, tmp_path):
    # b = 5 above a random policy's episode cost, so ν falls from 0.5 every iteration: a ν, Adam
    # moments and a window that are not trivially their initial values. One env: episodes complete.
    algo = config(train_batch_size_per_learner=400, minibatch_size=100, num_epochs=2, nu_init=0.5,
                  cost_limit=5.0, num_envs_per_env_runner=1).build_algo()
    restored = None
    try:
        results = [algo.train() for _ in range(2)]
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        restored = PPOLag.from_checkpoint(path)
        learners = [a.learner_group._learner for a in (algo, restored)]
        before, after = (learner.get_state(not_components="metrics_logger") for learner in learners)
        flat_before, flat_after = _flat(before), _flat(after)
        assert flat_before.keys() == flat_after.keys()
        for k in flat_before:
            np.testing.assert_array_equal(np.asarray(flat_before[k]), np.asarray(flat_after[k]), err_msg=k)
        rule = learners[1].multipliers[DEFAULT_MODULE_ID].rule
        window = list(learners[1].cost_windows[DEFAULT_MODULE_ID])
        assert rule.t == 2 and rule.m != 0 and len(window) >= 4, (rule.get_state(), window)
        nus = [float(learner.module[DEFAULT_MODULE_ID].nu) for learner in learners]
        assert nus[0] == nus[1] == pytest.approx(results[-1][NU]) and nus[0] < 0.5
        # The next step of ν (one more episode of cost 9) is the same from the original and the restore.
        for learner in learners:
            learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [9.0]})
        assert float(learners[0].module[DEFAULT_MODULE_ID].nu) == float(learners[1].module[DEFAULT_MODULE_ID].nu)
        assert list(learners[0].cost_windows[DEFAULT_MODULE_ID]) == list(learners[1].cost_windows[DEFAULT_MODULE_ID])
        # The env runners act with the restored ν and weights; the run keeps training from there.
        assert float(restored.env_runner.module.nu) == nus[1]
        with open(os.path.join(path, "rllib_checkpoint.json")) as f:
            meta = json.load(f)
        assert meta["algo"] == "ppo_lag" and meta["task_id"] == "lac/PointHazard-v0" and meta["cost_limit"] == 5.0
        assert meta["algo_config"]["nu_init"] == 0.5 and meta["algo_config"]["preset"] == "tiny"
        # Evaluation restores the learner's full module without Ray; it acts like the trained one.
        module = RLModule.from_checkpoint(os.path.join(path, "learner_group", "learner", "rl_module",
                                                       DEFAULT_MODULE_ID))
        obs = torch.randn(8, 7)
        assert torch.equal(module.deterministic_action(obs), learners[0].module[DEFAULT_MODULE_ID]
                           .deterministic_action(obs)) and float(module.nu) == nus[0]
        restored.train()
    finally:
        algo.stop()
        if restored is not None:
            restored.stop()


def test_the_module_roles_and_its_deterministic_action(ray_session):
    algo = config(train_batch_size_per_learner=200, minibatch_size=100, num_epochs=1).build_algo()
    try:
        learner_module = algo.learner_group._learner.module[DEFAULT_MODULE_ID]
        runner_module = algo.env_runner.module
        assert hasattr(learner_module, "cost_vf") and learner_module.encoder.critic_encoder is not None
        assert not hasattr(runner_module, "cost_vf") and not hasattr(runner_module, "vf")
        obs = torch.randn(16, 7)
        with torch.no_grad():
            inputs = runner_module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
        mean = inputs[:, :2]
        # Box(−1, 1): RLlib's unsquash of the mean is the mean, clipped (to float rounding).
        torch.testing.assert_close(learner_module.deterministic_action(obs), mean.clamp(-1, 1))
    finally:
        algo.stop()


def test_the_policy_lr_at_a_fifth_of_its_horizon_read_from_the_optimizers(ray_session):
    # 400 steps per iteration over a horizon of 2000 (the run's own budget, 10k, is five times longer,
    # as a 1e7 horizon is to a 2.5M run): after one iteration the lifetime count is 1/5 of the
    # horizon, so the policy's lr is 4/5 of its start; the critics' lr does not decay.
    algo = config(train_batch_size_per_learner=400, minibatch_size=200, num_epochs=1, lr=1e-3, critic_lr=5e-4,
                  lr_decay_horizon=2_000, num_envs_per_env_runner=1).build_algo()
    try:
        algo.train()
        lrn = algo.learner_group._learner  # the local learner, as the checkpoint test reads it
        lrs = {name: opt.param_groups[0]["lr"] for name, opt in lrn.get_optimizers_for_module(DEFAULT_MODULE_ID)}
        assert lrs[POLICY] == pytest.approx(1e-3 * (1 - 400 / 2_000), rel=1e-6), lrs
        assert lrs[CRITIC] == lrs[COST_CRITIC] == 5e-4, lrs
    finally:
        algo.stop()
