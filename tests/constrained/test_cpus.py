"""constrained/cpus.py: each remote env runner's torch ops on one thread, whatever the run's
OMP_NUM_THREADS (a 2-CPU run started with 2 ran at half speed: docs/speed.md)."""

import types

import pytest
import torch

from lac_rllib.algorithms.registry import ALGOS, build_config
from lac_rllib.constrained.cpus import OneThreadPerEnvRunner


@pytest.fixture
def threads():
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("worker_index, expected", [(1, 1), (2, 1), (0, 2)])
def test_remote_env_runners_get_one_thread_the_drivers_keeps_its_own(threads, worker_index, expected):
    torch.set_num_threads(2)  # as OMP_NUM_THREADS=2 leaves a Ray actor
    OneThreadPerEnvRunner().on_environment_created(env_runner=types.SimpleNamespace(worker_index=worker_index),
                                                   env=None, env_context=None, metrics_logger=None)
    assert torch.get_num_threads() == expected


@pytest.mark.parametrize("algo", list(ALGOS))
def test_every_algorithm_runs_the_hook_on_its_env_runners(algo):
    config = build_config(algo, "lac/PointHazard-v0", 0, {"num_envs_per_env_runner": 2}, timesteps=100_000, cpus=2)
    assert OneThreadPerEnvRunner in config.callbacks_class
    assert config.num_env_runners == 2


@pytest.mark.parametrize("algo", ["lac", "ppo_lag", "sac_lag", "focops"])
def test_every_learner_leaves_fresh_tensors_unfilled_under_rllibs_determinism(ray_session, threads, algo):
    """RLlib's seeding turns torch's deterministic algorithms on, whose default NaN-fills every
    tensor torch.empty makes; each learner turns the fill off (learner_torch), determinism stays."""
    torch.utils.deterministic.fill_uninitialized_memory = True
    algo = build_config(algo, "lac/PointHazard-v0", 0, {}, timesteps=100_000).build_algo()
    try:
        assert torch.are_deterministic_algorithms_enabled()  # RLlib's, for the seed
        assert torch.utils.deterministic.fill_uninitialized_memory is False
        assert torch.get_num_threads() == algo.config.torch_threads
    finally:
        algo.stop()


def _flushes() -> bool:
    """Whether this process flushes denormals: a denormal float32 product reads 0."""
    tiny = torch.tensor([1e-30], dtype=torch.float32)
    return bool((tiny * 1e-10 == 0).all())


@pytest.mark.parametrize("flush", [True, False])
def test_sac_lags_flush_denormal_field_sets_the_learners_process(ray_session, flush):
    """flush_denormal=True flushes denormals in the learner's process, False (the default) leaves
    them, whatever an earlier learner in the process set."""
    torch.set_flush_denormal(not flush)
    algo = build_config("sac_lag", "lac/PointHazard-v0", 0, {"flush_denormal": flush}, timesteps=100_000).build_algo()
    try:
        assert _flushes() is flush
    finally:
        algo.stop()
        torch.set_flush_denormal(False)
