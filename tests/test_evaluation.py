"""lac_rllib.evaluation: restore a LAC checkpoint without Ray and evaluate it deterministically."""

import json
import os
import pickle
import re
import shutil

import numpy as np
import pytest
import torch

from lac_rllib.algorithms.registry import algos_text
from lac_rllib.constrained.algorithm import CHECKPOINT_FORMAT
from lac_rllib.evaluation import (
    CheckpointError,
    _Recorder,
    _write_video,
    evaluate,
    restore_policy,
)

# One worker runs this module: its module-scoped fixture is expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("evaluation"), pytest.mark.slow]

TASK = "lac/PointHazard-v0"


@pytest.fixture(scope="module")
def policy(checkpoint):
    return restore_policy(checkpoint)


@pytest.fixture
def ckpt_copy(checkpoint, tmp_path):
    dst = tmp_path / "checkpoint"
    shutil.copytree(checkpoint, dst)
    return dst


def _edit_metadata(ckpt_dir, **changes):
    file = ckpt_dir / "rllib_checkpoint.json"
    meta = json.loads(file.read_text())
    meta.update(changes)
    file.write_text(json.dumps(meta))


# ----------------------------------------------------------------------------- metadata, restore


def test_checkpoint_metadata_written_by_lac(checkpoint):
    from importlib.metadata import version

    meta = json.loads(open(os.path.join(checkpoint, "rllib_checkpoint.json")).read())
    assert meta["lac_rllib_version"] == version("lac-rllib")
    assert meta["checkpoint_format"] == CHECKPOINT_FORMAT == 4
    assert meta["task_id"] == TASK
    assert meta["cost_limit"] == 2.0 and meta["episode_cost_discount"] == 1.0
    assert meta["algo_config"]["env_steps_per_iteration"] == 500
    assert meta["algo_config"]["actor_hidden"] == [64, 64]  # tiny preset, JSON list
    assert meta["checkpoint_version"] == "2.1"  # RLlib's own keys are kept


def test_restore_gives_full_module_and_frozen_filter(policy, checkpoint):
    m = policy.module
    assert policy.task_id == TASK and policy.cost_limit == 2.0 and policy.episode_cost_discount == 1.0
    assert policy.algo_config["replay_capacity"] == 2000
    assert not m.inference_only and hasattr(m, "critics") and hasattr(m, "target_actor")
    # Every tensor equals the learner's saved module state, target networks and ν included.
    saved = pickle.load(open(os.path.join(
        checkpoint, "learner_group/learner/rl_module/default_policy/module_state.pkl"), "rb"))
    state = m.state_dict()
    assert set(state) == set(saved)
    for key, value in saved.items():
        np.testing.assert_array_equal(state[key].numpy(), np.asarray(value), err_msg=key)
    assert any(k.startswith("target_critics.") for k in saved)
    assert float(m.nu) == pytest.approx(float(saved["nu"]))
    # The observation filter: the env runner's saved statistics, not updating.
    saved_filter = pickle.load(open(os.path.join(
        checkpoint, "env_runner/env_to_module_connector/FlooredMeanStdFilter/state.pkl"), "rb"))
    assert policy.obs_filter.get_state()[None]["running_stats"] == saved_filter[None]["running_stats"]
    assert policy.obs_filter.get_ctor_args_and_kwargs()[1]["update_stats"] is False
    assert policy.obs_filter.get_ctor_args_and_kwargs()[1]["clip_by_value"] == 5.0
    assert policy.obs_filter.get_ctor_args_and_kwargs()[1]["std_floor"] == 1e-2  # docs/spec.md §5, kept frozen


def test_restore_accepts_the_train_output_dir(checkpoint):
    assert restore_policy(os.path.dirname(checkpoint)).checkpoint_path == checkpoint


def test_preprocess_normalises_and_clips(policy):
    from ray.rllib.utils.filter import RunningStat

    stats = RunningStat.from_state(policy.obs_filter.get_state()[None]["running_stats"][0])
    raw = np.array([[-1.0, 0.0, 2.0, 0.0, 1.0, 0.0, 0.65], [50.0, 0, 0, 0, 0, 0, 0]], dtype=np.float32)
    expected = np.clip((raw - stats.mean) / np.maximum(stats.std, 1e-2), -5, 5)  # std floored (docs/spec.md §5)
    np.testing.assert_allclose(policy.preprocess(raw).numpy(), expected, rtol=1e-4, atol=1e-4)
    assert policy.preprocess(raw).numpy()[1, 0] == 5.0  # clipped


# ----------------------------------------------------------------------------- evaluate


def test_generator_evaluation_is_deterministic(policy):
    before = policy.obs_filter.get_state()
    a = evaluate(policy, 3, seed=7, progress=False)
    b = evaluate(policy, 3, seed=7, progress=False)
    c = evaluate(policy, 3, seed=8, progress=False)
    assert a == b
    assert a["returns"] != c["returns"]
    # Episode i uses seed + i: seed 8's first two episodes are seed 7's last two.
    assert c["returns"][:2] == a["returns"][1:]
    assert policy.obs_filter.get_state()[None]["running_stats"] == before[None]["running_stats"]
    assert len(a["returns"]) == len(a["costs"]) == 3 and a["lengths"] == [100, 100, 100]
    assert a["return_mean"] == pytest.approx(np.mean(a["returns"]))
    assert a["cost_std"] == pytest.approx(np.std(a["costs"]))
    assert a["cost_limit"] == 2.0
    assert a["within_limit_fraction"] == np.mean([x <= 2.0 for x in a["costs"]])
    assert "energy_refined_mean" not in a


def test_langevin_evaluation_is_deterministic_and_lowers_energy(policy):
    a = evaluate(policy, 2, seed=3, actions="langevin", progress=False)
    b = evaluate(policy, 2, seed=3, actions="langevin", progress=False)
    c = evaluate(policy, 2, seed=4, actions="langevin", progress=False)
    assert a == b
    assert a["returns"] != c["returns"]
    assert a["langevin_steps"] == 10 and a["langevin_step_size"] == 1e-4  # the checkpoint's T, η
    assert a["energy_refined_mean"] < a["energy_generator_mean"]
    assert a["action_displacement_mean"] > 0
    d = evaluate(policy, 2, seed=3, actions="langevin", langevin_steps=3, langevin_step_size=1e-5,
                 progress=False)
    assert d["langevin_steps"] == 3 and d["action_displacement_mean"] < a["action_displacement_mean"]


def _states(policy, n_episodes=3) -> torch.Tensor:
    """A fixed batch of states: uniform-random-action rollouts, filtered like the policy's."""
    from lac_rllib.tasks import get_task

    env, rng, raw = get_task(policy.task_id).make({}), np.random.default_rng(0), []
    for i in range(n_episodes):
        obs, _ = env.reset(seed=100 + i)
        done = False
        while not done:
            raw.append(obs)
            obs, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            done = terminated or truncated
    return policy.preprocess(np.asarray(raw))


def test_langevin_refined_actions_have_lower_energy_on_a_fixed_batch(policy):
    m, s = policy.module, _states(policy)
    decrease, moved = [], []
    with torch.no_grad():
        t_mean, t_log_std = m.target_actor(s)
        gen_mean = m.actor(s)[0]
        for k in range(4):  # several chains per state
            chain = m.langevin(s, t_mean, t_log_std, generator=torch.Generator().manual_seed(k))
            decrease.append((chain.energy_start - chain.energy_end).numpy())
            moved.append((chain.action - gen_mean).norm(dim=-1).numpy())
            assert torch.all(chain.action <= 1) and torch.all(chain.action >= -1)
    d = np.concatenate(decrease)
    stderr = d.std() / np.sqrt(len(d))
    assert d.mean() > 5 * stderr, (d.mean(), stderr)  # measured ≈ 10 standard errors
    assert np.concatenate(moved).min() > 1e-4  # refined actions differ from the generator's


# ----------------------------------------------------------------------------- video


def test_no_renderer_gives_a_notice_and_continues(policy, tmp_path, capsys):
    r = evaluate(policy, 1, seed=0, video_dir=str(tmp_path / "v"), progress=False)
    assert r["videos"] == [] and "has no renderer" in r["video_notice"]
    assert "continuing without video" in capsys.readouterr().err
    assert r["lengths"] == [100]


def test_recorder_bounds_frames_and_writes_a_video(tmp_path):
    class FakeEnv:
        def __init__(self):
            self.n = 0

        def render(self):
            self.n += 1
            return np.full((480, 480, 3), self.n % 255, dtype=np.uint8)

    env = FakeEnv()
    rec = _Recorder(env)  # no time limit: the stride doubles as frames pile up
    for t in range(1000):
        rec.capture(t)
    assert len(rec.frames) < 400 and rec.frames[0].shape == (240, 240, 3) and rec.stride > 1
    path = _write_video(rec.frames[:5], str(tmp_path / "ep"), fps=10)
    assert os.path.getsize(path) > 0 and path.endswith((".gif", ".mp4"))


# ----------------------------------------------------------------------------- errors


def test_missing_path(tmp_path):
    with pytest.raises(CheckpointError, match="checkpoint not found"):
        restore_policy(str(tmp_path / "nope"))
    with pytest.raises(CheckpointError, match="not an RLlib checkpoint"):
        restore_policy(str(tmp_path))


def test_version_mismatch(ckpt_copy):
    _edit_metadata(ckpt_copy, lac_rllib_version="9.9.0")
    with pytest.raises(CheckpointError, match=r"version mismatch: written by lac-rllib 9\.9\.0"):
        restore_policy(str(ckpt_copy))


def test_patch_version_difference_is_accepted(ckpt_copy):
    from importlib.metadata import version

    major, minor = version("lac-rllib").split(".")[:2]
    _edit_metadata(ckpt_copy, lac_rllib_version=f"{major}.{minor}.99")
    assert restore_policy(str(ckpt_copy)).task_id == TASK


def test_format_mismatch(ckpt_copy):
    _edit_metadata(ckpt_copy, checkpoint_format=1)
    with pytest.raises(CheckpointError, match=r"unsupported checkpoint format 1 .*\(written by lac-rllib "
                                              r"[\d.]+\): this lac-rllib .* reads formats 4 and 2 and 3"):
        restore_policy(str(ckpt_copy))


def test_a_format_2_checkpoint_restores_with_its_old_key(ckpt_copy):
    """Format 2 (before the rename) kept the algorithm's fields under ``lac_config``."""
    file = ckpt_copy / "rllib_checkpoint.json"
    meta = json.loads(file.read_text())
    fields = meta.pop("algo_config")
    file.write_text(json.dumps({**meta, "checkpoint_format": 2, "lac_config": fields}))
    policy = restore_policy(str(ckpt_copy))
    assert policy.algo_config == fields and policy.task_id == TASK


def test_an_algorithm_not_importable_here_is_one_line(ckpt_copy):
    """A user's algorithm is imported again by the path the checkpoint names: gone, it is said so."""
    _edit_metadata(ckpt_copy, algo="gone.safe_algo")
    with pytest.raises(CheckpointError, match=r"^checkpoint algorithm is not available here: unknown algo "
                                              r"'gone.safe_algo'; accepted: " + re.escape(algos_text()) + ", or the "):
        restore_policy(str(ckpt_copy))


def test_not_a_lac_checkpoint(ckpt_copy):
    file = ckpt_copy / "rllib_checkpoint.json"
    meta = {k: v for k, v in json.loads(file.read_text()).items() if not k.startswith(("lac", "checkpoint_f"))}
    file.write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="not a lac-rllib checkpoint"):
        restore_policy(str(ckpt_copy))


def test_unreadable_metadata(ckpt_copy):
    (ckpt_copy / "rllib_checkpoint.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="corrupt checkpoint: metadata .* is unreadable"):
        restore_policy(str(ckpt_copy))


def test_missing_module_files(ckpt_copy):
    module_dir = ckpt_copy / "learner_group/learner/rl_module/default_policy"
    (module_dir / "module_state.pkl").unlink()
    with pytest.raises(CheckpointError, match="corrupt checkpoint: cannot restore the RLModule"):
        restore_policy(str(ckpt_copy))
    shutil.rmtree(ckpt_copy / "learner_group")
    with pytest.raises(CheckpointError, match="corrupt checkpoint: module directory .* is missing"):
        restore_policy(str(ckpt_copy))


def test_module_state_without_critics(ckpt_copy):
    file = ckpt_copy / "learner_group/learner/rl_module/default_policy/module_state.pkl"
    state = pickle.loads(file.read_bytes())
    file.write_bytes(pickle.dumps({k: v for k, v in state.items() if not k.startswith("critics.")}))
    with pytest.raises(CheckpointError, match=r"missing or non-finite .* critics\."):
        restore_policy(str(ckpt_copy))


def test_missing_filter_state(ckpt_copy):
    shutil.rmtree(ckpt_copy / "env_runner")
    with pytest.raises(CheckpointError, match="observation-filter directory .* is missing"):
        restore_policy(str(ckpt_copy))


def test_bad_arguments(policy):
    with pytest.raises(ValueError, match="actions="):
        evaluate(policy, 1, 0, actions="greedy")
    with pytest.raises(ValueError, match="episodes="):
        evaluate(policy, 0, 0)


# ----------------------------------------------------------------------------- the stochastic mode


def test_the_deterministic_mode_acts_with_the_mean_and_the_stochastic_one_samples(policy, monkeypatch):
    """A stub mean: the env receives exactly it with actions='generator'; the stochastic mode's
    actions are samples around the policy (not the stub), the same for the same seed."""
    from lac_rllib.tasks.point_hazard import PointHazardEnv

    seen = []
    step = PointHazardEnv.step

    def record(self, action):
        seen.append(np.asarray(action, dtype=np.float64).copy())
        return step(self, action)

    monkeypatch.setattr(PointHazardEnv, "step", record)
    stub = torch.tensor([[0.25, -0.5]])
    monkeypatch.setattr(policy.module, "deterministic_action", lambda obs: stub.expand(len(obs), -1))
    evaluate(policy, 1, seed=7, actions="generator", progress=False)
    assert seen and all(np.allclose(a, [0.25, -0.5]) for a in seen)
    seen.clear()
    first = evaluate(policy, 2, seed=7, actions="stochastic", progress=False)
    sampled = [a.copy() for a in seen]
    assert not all(np.allclose(a, [0.25, -0.5]) for a in sampled) and len({tuple(a) for a in sampled}) > 1
    seen.clear()
    again = evaluate(policy, 2, seed=7, actions="stochastic", progress=False)
    assert again["returns"] == first["returns"] and all(np.array_equal(a, b) for a, b in zip(sampled, seen))
    assert "stochastic" in policy.actions and policy.actions[0] == "generator"


def test_the_evaluation_blocks_env_seeds_are_disjoint_from_training(ray_session, monkeypatch, tmp_path):
    """Every env reset of a trial's training and of its evaluation block, recorded: the block's
    episodes start at eval_seed(seed) and share no seed with training; N episodes per mode."""
    from lac_rllib.algorithms.registry import build_config
    from lac_rllib.tasks.point_hazard import PointHazardEnv
    from sweeps.trainable import eval_seed, evaluation_block

    seeds = []
    reset = PointHazardEnv.reset

    def record(self, *, seed=None, options=None):
        seeds.append(seed)
        return reset(self, seed=seed, options=options)

    monkeypatch.setattr(PointHazardEnv, "reset", record)
    algo = build_config("ppo_lag", TASK, 3, {"train_batch_size_per_learner": 400, "minibatch_size": 100,
                                             "num_epochs": 1, "num_envs_per_env_runner": 2},
                        timesteps=1000).build_algo()  # env runner in this process: its resets recorded
    try:
        for _ in range(2):
            algo.train()
        path = algo.save_to_path(str(tmp_path / "ckpt"))
    finally:
        algo.stop()
    training = {s for s in seeds if s is not None}
    assert training, "the training envs were seeded"
    seeds.clear()
    results = evaluation_block(path, 3, seed=3)
    assert [r["actions"] for r in results] == ["generator", "stochastic"] and all(r["episodes"] == 3 for r in results)
    assert seeds == [eval_seed(3) + i for i in range(3)] * 2 and not training & set(seeds)


@pytest.mark.parametrize("algo, modes, robot", [("ppo_lag", ("generator", "stochastic"), "safety_gym"),
                                                ("lac", ("langevin",), "safety_gymnasium")])
def test_a_batched_task_plays_its_episodes_together_as_one_env_plays_them(ray_session, monkeypatch, tmp_path,
                                                                         algo, modes, robot):
    """On the batched backend the evaluation plays its episodes in one vector env (3 here); every
    episode's return, cost and length equal the stock env's, one episode at a time, in each mode.
    The checkpoint carries the env it trained on (its robot), and the evaluation builds that one."""
    from lac_rllib.algorithms.registry import build_config
    from lac_rllib.evaluation import _lanes
    from lac_rllib.tasks.batched_navigation import BatchedNavigationEnv

    trainer = build_config(algo, "SafetyPointGoal1-v0", 0, {"robot_variant": robot}, timesteps=10_000).build_algo()
    try:
        path = trainer.save_to_path(str(tmp_path / "ckpt"))
    finally:
        trainer.stop()
    policy = restore_policy(path)
    assert policy.env_config["env_backend"] == "batched" and _lanes(policy, 3) == 3
    assert policy.env_config["robot_variant"] == robot
    steps, step = [], BatchedNavigationEnv.step
    monkeypatch.setattr(BatchedNavigationEnv, "step", lambda self, a: steps.append(len(a)) or step(self, a))
    for mode in modes:
        policy.env_config.update(env_backend="batched", max_episode_steps=40)
        together = evaluate(policy, 3, seed=5, actions=mode, progress=False)
        assert steps and set(steps) == {3}  # one vector env of 3 played them
        steps.clear()
        policy.env_config["env_backend"] = "stock"
        alone = evaluate(policy, 3, seed=5, actions=mode, progress=False)
        assert not steps
        assert together["lengths"] == alone["lengths"] == [40] * 3
        assert together["returns"] == alone["returns"] and together["costs"] == alone["costs"]
        assert len(set(together["returns"])) == 3  # three different episodes


def test_a_checkpoint_with_several_constraints_evaluates_each(ray_session, tmp_path):
    """LAC trained with a limit per constraint on lac/PointTwoCosts-v0 restores, and its evaluation
    reports each constraint's episode costs (they sum to the summed cost there), limit and share of
    episodes within, and the share within both; lac-eval prints a line per constraint."""
    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.train import train
    from sweeps.evaluate import format_human

    config = LACConfig.build("lac/PointTwoCosts-v0", 0, {"env_steps_per_iteration": 500, "replay_capacity": 2000,
                                                         "random_iterations": 1,
                                                         "constraints": {"hazard": 2.0, "lane": 10.0}},
                             timesteps=1000)
    train(config, 1000, str(tmp_path / "run"), log=lambda *a, **k: None)
    policy = restore_policy(str(tmp_path / "run" / "checkpoint"))
    assert policy.module.nu.shape == (2,) and policy.constraint_set.names == ("hazard", "lane")
    result = evaluate(policy, 3, seed=5, progress=False)
    hazard, lane = result["constraints"]["hazard"], result["constraints"]["lane"]
    assert [h + la for h, la in zip(hazard["costs"], lane["costs"])] == pytest.approx(result["costs"])
    assert (hazard["cost_limit"], lane["cost_limit"]) == (2.0, 10.0)
    both = [h <= 2.0 and la <= 10.0 for h, la in zip(hazard["costs"], lane["costs"])]
    assert result["within_all_limits_fraction"] == pytest.approx(sum(both) / 3)
    text = format_human(result, "x")
    assert "  lane" in text and "within all" in text
    langevin = evaluate(policy, 1, seed=5, actions="langevin", progress=False)
    assert len(langevin["nu"]) == 2 and "nu=" in format_human(langevin, "x")
