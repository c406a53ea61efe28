"""LAC inside RLlib: cost alignment, ν from completed episodes, module roles, checkpoints."""


import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

from conftest import tiny_config, train_batch
from lac_rllib.algorithm import LAC
from lac_rllib.connectors import COSTS

PROBE = "lac/CostProbe-v0"  # cost of step t = 2t + 1, obs = t, reward = −t, 7-step episodes


@pytest.mark.parametrize("num_env_runners", [0, 1])
def test_every_train_row_carries_its_own_cost(ray_session, num_env_runners):
    # 50 steps per iteration with 7-step episodes: chunks are cut mid-episode every time.
    config = tiny_config(PROBE, obs_normalization=False, env_steps_per_iteration=50,
                         replay_capacity=1000, lac_minibatch_size=16)
    config.env_runners(num_env_runners=num_env_runners)
    algo = config.build_algo()
    try:
        for _ in range(3):
            result = algo.train()
        b = train_batch(algo)
        t = b[Columns.OBS][:, 0]
        assert len(t) == 150
        np.testing.assert_array_equal(b[COSTS], 2 * t + 1)
        np.testing.assert_array_equal(b[Columns.REWARDS], -t)
        np.testing.assert_array_equal(b[Columns.NEXT_OBS][:, 0], t + 1)
        np.testing.assert_array_equal(b[Columns.TERMINATEDS], t == 6)
        # Episode totals cross chunk boundaries: Σ_{t<7} (2t+1) = 49, Σ −t = −21.
        assert result["episode_cost"] == 49.0 and result["episode_return"] == -21.0
    finally:
        algo.stop()


def test_nu_follows_completed_episodes_only(ray_session):
    config = tiny_config(PROBE, obs_normalization=False, env_steps_per_iteration=50, cost_limit=40.0,
                         nu_lr=0.01, replay_capacity=1000, lac_minibatch_size=16)
    algo = config.build_algo()
    try:
        # 7 complete episodes (Ĵ_C = 49 each) and a partial one per batch: ν += 0.01·(49 − 40).
        assert algo.train()["nu"] == pytest.approx(0.09, abs=1e-6)
        assert algo.train()["nu"] == pytest.approx(0.18, abs=1e-6)
        # No completed episode → no ν step.
        learner = algo.learner_group._learner
        learner.before_gradient_based_update(timesteps={"lac_episode_cost": None})
        assert float(learner.module[DEFAULT_MODULE_ID].nu) == pytest.approx(0.18, abs=1e-6)
    finally:
        algo.stop()


def test_module_roles(ray_session):
    algo = tiny_config(env_steps_per_iteration=200).build_algo()
    try:
        learner_module = algo.learner_group._learner.module[DEFAULT_MODULE_ID]
        runner_module = algo.env_runner.module
        assert hasattr(learner_module, "critics") and hasattr(learner_module, "target_critics")
        assert not hasattr(runner_module, "critics"), "critics must not ship to env runners"
        assert not hasattr(runner_module, "target_actor")
        obs = torch.randn(64, 7)
        with torch.no_grad():
            inf = learner_module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
            mean, log_std = learner_module.actor(obs)
        dist_cls = learner_module.get_inference_action_dist_cls()
        det = dist_cls.from_logits(inf).to_deterministic().sample()
        torch.testing.assert_close(det, mean)  # inference acts with the generator's mean
        samples = dist_cls.from_logits(inf).sample()
        assert not torch.allclose(samples, mean)  # exploration samples
        torch.testing.assert_close(samples.std(0).mean(), log_std.exp().mean(), rtol=0.3, atol=0)
    finally:
        algo.stop()


def _flat(tree, prefix=""):
    out = {}
    if isinstance(tree, dict):
        for k, v in tree.items():
            out.update(_flat(v, f"{prefix}/{k}"))
    elif isinstance(tree, (list, tuple)) and tree and not np.isscalar(tree[0]):
        for i, v in enumerate(tree):
            out.update(_flat(v, f"{prefix}/{i}"))
    else:
        out[prefix] = tree
    return out


def _assert_tree_equal(a, b, what):
    fa, fb = _flat(a), _flat(b)
    assert fa.keys() == fb.keys(), what
    for k in fa:
        va, vb = fa[k], fb[k]
        if isinstance(va, (np.ndarray, torch.Tensor)) or isinstance(vb, (np.ndarray, torch.Tensor)):
            np.testing.assert_array_equal(np.asarray(va), np.asarray(vb), err_msg=f"{what}{k}")
        else:
            assert va == vb, f"{what}{k}: {va!r} != {vb!r}"


def test_checkpoint_round_trip(ray_session, tmp_path):
    # ν starts away from 0 so its round trip is not trivially 0 == 0.
    config = tiny_config(env_steps_per_iteration=300, random_iterations=1, actor_update_start_iteration=0,
                         nu_init=0.7)
    algo = config.build_algo()
    try:
        for _ in range(2):
            algo.train()
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        before = {
            "learner": algo.learner_group.get_state(not_components="metrics_logger"),
            "filter": algo.env_runner.get_state()["env_to_module_connector"],
        }
        steps = algo.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME))
        obs = torch.randn(32, 7)
        with torch.no_grad():
            act_before = algo.get_module().actor(obs)[0]
        nu_before = float(algo.get_module().nu)
        iteration = algo.iteration
    finally:
        algo.stop()
    assert nu_before > 0, "the test needs a non-trivial ν"

    restored = LAC.from_checkpoint(path)
    try:
        after = {
            "learner": restored.learner_group.get_state(not_components="metrics_logger"),
            "filter": restored.env_runner.get_state()["env_to_module_connector"],
        }
        _assert_tree_equal(before, after, "state")
        assert any("optimizer" in k for k in _flat(after)), "optimizer state must be checkpointed"
        assert float(restored.get_module().nu) == nu_before
        assert restored.iteration == iteration
        assert restored.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME)) == steps
        with torch.no_grad():
            torch.testing.assert_close(restored.get_module().actor(obs)[0], act_before, rtol=0, atol=0)
        restored.train()  # and it keeps training from there
    finally:
        restored.stop()
