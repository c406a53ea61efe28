"""What every baseline on PPO-Lag's house must do inside RLlib, one test per claim, each run for the
first-order ones (FOCOPS, CUP, P3O, RESPO) and the trust-region ones (TRPO-Lag, CPO, PCPO): each
train row carries its own cost, a checkpoint round trip continues with an identical next
iteration, and the registry names it everywhere."""

import copy

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns

from lac_rllib.algorithms import registry
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import COST_RATE, ENV_STEPS, EPISODE_COST, EPISODE_RETURN, NU
from lac_rllib.families.on_policy import algorithm as on_policy_algorithm

FIRST_ORDER = ("focops", "cup", "p3o", "respo")
TRUST_REGION = ("trpo_lag", "cpo", "pcpo")
ON_POLICY = FIRST_ORDER + TRUST_REGION
PROBE = "lac/CostProbe-v0"  # cost of step t = 2t + 1, obs = t, reward = −t, 7-step episodes
SMALL = {"train_batch_size_per_learner": 200, "minibatch_size": 50, "num_epochs": 2, "num_envs_per_env_runner": 1}


def build(algo, task="lac/PointHazard-v0", **sets):
    return registry.build_config(algo, task, 0, {**SMALL, **sets}, timesteps=10_000).build_algo()


def _flat(tree, prefix=""):
    if isinstance(tree, dict):
        return {k2: v2 for k, v in tree.items() for k2, v2 in _flat(v, f"{prefix}/{k}").items()}
    if isinstance(tree, (list, tuple)) and tree and not np.isscalar(tree[0]):
        return {k2: v2 for i, v in enumerate(tree) for k2, v2 in _flat(v, f"{prefix}/{i}").items()}
    return {prefix: tree}


@pytest.mark.parametrize("algo", ON_POLICY)
def test_every_train_row_carries_its_own_cost(ray_session, monkeypatch, algo):
    # 50 steps per iteration with 7-step episodes: chunks are cut mid-episode every time.
    learner_class = registry.build_config(algo, PROBE, 0, {}, timesteps=1000).get_default_learner_class()
    seen, original = [], learner_class.compute_loss_for_module

    def record(self, *, module_id, config, batch, fwd_out):
        seen.append({k: v.detach().numpy().copy() for k, v in batch.items() if isinstance(v, torch.Tensor)})
        return original(self, module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)

    monkeypatch.setattr(learner_class, "compute_loss_for_module", record)
    a = build(algo, PROBE, obs_normalization=False, train_batch_size_per_learner=50, minibatch_size=None,
              num_epochs=1)
    try:
        for _ in range(3):
            result = a.train()
    finally:
        a.stop()
    assert seen, "the loss never ran"
    for b in seen:
        real, t = b[Columns.LOSS_MASK], b[Columns.OBS][:, 0]
        np.testing.assert_array_equal(b[COSTS][real], 2 * t[real] + 1)
        np.testing.assert_array_equal(b[Columns.REWARDS][real], -t[real])
        assert not b[COSTS][~real].any(), "the phantom row repeats the last info; its cost must be 0"
    assert result[EPISODE_COST] == 49.0 and result[EPISODE_RETURN] == -21.0 and np.isfinite(result[NU])
    # The training's cost per env step: 49 per 7-step episode, the episodes not yet completed not counted.
    assert 6.5 < result[COST_RATE] <= 7.0 and result[COST_RATE] == result["cost_total"] / result[ENV_STEPS]


@pytest.mark.parametrize("algo", ON_POLICY)
def test_a_checkpoint_round_trip_gives_an_identical_next_iteration(ray_session, monkeypatch, tmp_path, algo):
    """After 2 iterations: save, restore, and train one more iteration on the same sampled episodes
    from the original and from the restored algorithm: every learner tensor (weights, optimizer
    moments, ν) and the multiplier's state come out identical. b = 0.5 keeps the constraint active,
    so ν, its optimizer and the cost window are not at their initial values."""
    a = build(algo, cost_limit=0.5)
    restored = None
    try:
        for _ in range(2):
            a.train()
        path = a.save_to_path(str(tmp_path / "ckpt"))
        restored = type(a).from_checkpoint(path)
        episodes, metrics = on_policy_algorithm.synchronous_parallel_sample(
            worker_set=a.env_runner_group, max_env_steps=200, sample_timeout_s=None, _uses_new_env_runners=True,
            _return_metrics=True)
        monkeypatch.setattr(on_policy_algorithm, "synchronous_parallel_sample",
                            lambda **_: (copy.deepcopy(episodes), copy.deepcopy(metrics)))
        states = []
        for algorithm in (a, restored):
            np.random.seed(11)  # the minibatch shuffles draw from numpy's global RNG
            torch.manual_seed(11)
            algorithm.train()
            learner = algorithm.learner_group._learner
            states.append(_flat(learner.get_state(not_components="metrics_logger")))
        assert states[0].keys() == states[1].keys()
        for k in states[0]:
            np.testing.assert_array_equal(np.asarray(states[0][k]), np.asarray(states[1][k]), err_msg=k)
        nu = float(a.learner_group._learner.module[DEFAULT_MODULE_ID].nu)
        assert nu == float(restored.learner_group._learner.module[DEFAULT_MODULE_ID].nu)
    finally:
        a.stop()
        if restored is not None:
            restored.stop()


@pytest.mark.parametrize("algo", ON_POLICY)
def test_the_registry_names_it_everywhere(algo):
    module = registry.algo_config(algo)
    assert registry.check_algo(algo) == algo and algo in registry.algos_text()
    config = registry.build_config(algo, "SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert config.ALGO == algo and config.preset == "safety_gym"
    assert set(module.REPORTED_KEYS) >= {"policy_loss", "vf_loss", "cost_vf_loss"}
    assert registry.budget_fields(algo, "smoke", "safety_gym")["train_batch_size_per_learner"] == 500
    assert registry.actions(algo) == ("generator", "stochastic") and "torch_threads" in registry.speed_fields(algo)
    with pytest.raises(ValueError, match=f"unknown {module.FIELDS.what} config field 'nope'"):
        registry.parse_sets(algo, ["nope=1"])
