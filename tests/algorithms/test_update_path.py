"""update_path: the baselines' fused update (constrained/minibatch_loop.py, optim.py, gradients.py)
is RLlib's own update, bit for bit. Each algorithm trains three iterations from one seed both ways
on the tiny task; every weight and buffer of the module (ν included) must be equal, and the runs
must have moved the weights (so the comparison is not between two untouched networks)."""

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.metrics import LEARNER_RESULTS, NUM_MODULE_STEPS_TRAINED

from lac_rllib.algorithms.registry import build_config

CASES = {
    "ppo_lag": {},  # tiny preset: 2000-step iterations, 10 epochs of 250-row minibatches, critic L2, clip
    # The OmniSafe sizes that straddle epochs (64-row minibatches) and the KL early stop on.
    "ppo_lag-64": {"algo": "ppo_lag", "minibatch_size": 64, "num_epochs": 3, "target_kl": 0.001},
    # CUP's two stages, each with its KL stop: the skipped minibatches of both (below).
    "cup-64": {"algo": "cup", "minibatch_size": 64, "num_epochs": 3, "target_kl": 0.001},
    "sac_lag": {"random_env_steps": 400, "env_steps_per_iteration": 400},
    "sac_lag-shuffled": {"algo": "sac_lag", "random_env_steps": 400, "env_steps_per_iteration": 400,
                         "minibatch_draws": "shuffled_passes"},
    # The trust-region step on the whole batch, then the critics' minibatch epochs on either path.
    "trpo_lag": {"num_epochs": 3},
    "cpo": {"num_epochs": 3},
}


def _train(name, path, iterations=3):
    sets = dict(CASES[name])
    algo_name = sets.pop("algo", name)
    sets["update_path"] = path
    algo = build_config(algo_name, "lac/PointHazard-v0", 0, sets, timesteps=100_000).build_algo()
    try:
        init = {k: v.clone() for k, v in algo.learner_group._learner.module[DEFAULT_MODULE_ID].state_dict().items()}
        for _ in range(iterations):
            result = algo.train()
        module = algo.learner_group._learner.module[DEFAULT_MODULE_ID]
        return init, {k: v.clone() for k, v in module.state_dict().items()}, result
    finally:
        algo.stop()


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_the_fused_update_is_rllibs_bit_for_bit(ray_session, name):
    init, rllib, result_rllib = _train(name, "rllib")
    _, fused, result_fused = _train(name, "fused")
    assert sum(not torch.equal(init[k], rllib[k]) for k in init) >= len(init) // 2  # it trained
    different = [k for k in rllib if not torch.equal(rllib[k], fused[k])]
    assert not different, different
    trained = [r[LEARNER_RESULTS][DEFAULT_MODULE_ID][NUM_MODULE_STEPS_TRAINED] for r in (result_rllib, result_fused)]
    assert trained[0] == trained[1] > 0  # every minibatch's rows counted, as RLlib counts them


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ppo_lag-64", "cup-64"])
def test_minibatches_the_kl_stop_left_idle_are_skipped_and_change_nothing(ray_session, monkeypatch, name):
    """The fused loop skips the forward pass and losses of a minibatch that would step no network
    (OnPolicyTorchLearner.skip_minibatch): the weights and every reported figure are those of the
    loop that runs them all."""
    from lac_rllib.families.on_policy.learner import OnPolicyTorchLearner

    skipped, original = [], OnPolicyTorchLearner.skip_minibatch

    def counting(self, rows):
        skipped.append(original(self, rows))
        return skipped[-1]

    monkeypatch.setattr(OnPolicyTorchLearner, "skip_minibatch", counting)
    _, skipping, result_skipping = _train(name, "fused", iterations=2)
    assert 0 < sum(skipped) < len(skipped)  # the stop left minibatches idle, and not all of them
    monkeypatch.setattr(OnPolicyTorchLearner, "skip_minibatch", lambda self, rows: False)
    _, running, result_running = _train(name, "fused", iterations=2)
    different = [k for k in skipping if not torch.equal(skipping[k], running[k])]
    assert not different, different
    reported = [{k: v for k, v in r[LEARNER_RESULTS][DEFAULT_MODULE_ID].items() if isinstance(v, (int, float))
                 and "throughput" not in k} for r in (result_skipping, result_running)]
    assert len(reported[0]) > 10 and reported[0] == reported[1]
