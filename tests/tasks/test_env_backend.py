"""The navigation tasks train on the batched backend through RLlib's own door (gymnasium's vector
entry point), ``env_backend: stock`` selects gymnasium's SyncVectorEnv of stock envs, and seeded
training learns the same on both; the env fingerprint names the backend."""

import hashlib
import json

import numpy as np
import pytest
import torch

from lac_rllib.algorithms.registry import budget_fields, build_config
from lac_rllib.tasks.batched_navigation import BatchedNavigationEnv
from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id

TASK = "SafetyPointGoal1-v0"
#: Row keys that measure the clock (each backend's speed), not what was learned.
CLOCK = ("time", "timer", "duration", "throughput", "sample")


def _digest(value, h) -> None:
    if isinstance(value, dict):
        for k in sorted(value, key=str):
            h.update(str(k).encode())
            _digest(value[k], h)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _digest(v, h)
    elif isinstance(value, torch.Tensor):
        h.update(value.detach().cpu().contiguous().numpy().tobytes())
    else:
        h.update(repr(value).encode())


def test_the_config_picks_the_vector_entry_point_for_the_batched_backend_only():
    sets = budget_fields("ppo_lag", "smoke", "safety_gym")
    batched = build_config("ppo_lag", TASK, 0, sets)
    assert batched.gym_env_vectorize_mode == "vector_entry_point" and batched.env_config["env_backend"] == "batched"
    stock = build_config("ppo_lag", TASK, 0, {**sets, "env_backend": "stock"})
    assert stock.gym_env_vectorize_mode == "sync" and stock.env_config["env_backend"] == "stock"
    other = build_config("ppo_lag", "SafetyDoggoGoal1-v0", 0, sets)  # no batched backend: stock, unnamed
    assert other.gym_env_vectorize_mode == "sync" and "env_backend" not in other.env_config
    with pytest.raises(ValueError, match="env_backend.*'fast'.*batched.*stock"):
        build_config("ppo_lag", TASK, 0, {**sets, "env_backend": "fast"})


def test_the_fingerprint_names_the_backend_where_a_task_has_one():
    a, b = fingerprint(TASK, {"env_backend": "batched"}), fingerprint(TASK, {"env_backend": "stock"})
    assert a["env_backend"] == "batched" and fingerprint_id(a) != fingerprint_id(b)
    assert "env_backend" not in fingerprint("lac/PointHazard-v0", {"env_backend": "batched"})


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo_lag", "lac"])
def test_seeded_training_learns_the_same_on_both_backends(ray_session, algo):
    """Two iterations over 4 envs with 60-step episodes (so envs reset inside an iteration): the
    module's weights, the optimizers and every reported row hash the same on both backends."""
    digests = {}
    for backend in ("batched", "stock"):
        sets = {**budget_fields(algo, "smoke", "safety_gym"), "num_envs_per_env_runner": 4, "env_backend": backend}
        config = build_config(algo, TASK, 3, sets, timesteps=2_000)
        config.env_config["max_episode_steps"] = 60
        trainer = config.build_algo()
        try:
            env = trainer.env_runner.env.unwrapped
            assert isinstance(env, BatchedNavigationEnv) == (backend == "batched"), type(env)
            rows = []
            for _ in range(2):
                r = trainer.train()
                rows.append({k: v for k, v in r["env_runners"].items() if isinstance(v, (int, float, np.floating))
                             and not any(w in k for w in CLOCK)})
            learner = trainer.learner_group._learner
            h = hashlib.sha256()
            _digest({"module": {m: x.state_dict() for m, x in learner.module.items()},
                     "optim": {n: o.state_dict() for n, o in sorted(learner._named_optimizers.items())},
                     "rows": json.loads(json.dumps(rows, default=str))}, h)
            digests[backend] = h.hexdigest()
            assert any("episode_return_mean" in k for row in rows for k in row)  # episodes ended and were counted
        finally:
            trainer.stop()
    assert digests["batched"] == digests["stock"]
