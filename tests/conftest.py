"""One Ray start for the whole session (ray.init costs ~10 s and ~1.5 GiB here)."""

import os

import pytest

os.environ.setdefault("RAY_DEDUP_LOGS", "0")


@pytest.fixture(scope="session")
def ray_session():
    import ray

    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def one_torch_thread():
    """Thousands of tiny ops: intra-op threads only add sync overhead (10x on a busy 2-core box)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def tiny_config(task="lac/PointHazard-v0", seed=0, **overrides):
    """A LACConfig on a built-in task, sized for tests (lr decay over 10k steps unless given)."""
    from lac_rllib.algorithms.lac.config import LACConfig

    overrides = {"total_env_steps": 10_000, **overrides}
    return LACConfig().task(task).training(**overrides).debugging(seed=seed)


def train_batch(algo) -> dict:
    """The train batch LAC's learner builds from the whole replay buffer, as numpy columns."""
    import copy

    import torch
    from ray.rllib.core import DEFAULT_MODULE_ID

    learner = algo.learner_group._learner
    batch = learner._learner_connector(
        rl_module=learner.module, batch={}, episodes=[copy.copy(e) for e in algo.replay_buffer.episodes],
        shared_data={}, metrics=learner.metrics,
    )[DEFAULT_MODULE_ID]
    return {k: (v.numpy() if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


@pytest.fixture(scope="session")
def checkpoint(ray_session, tmp_path_factory):
    """One tiny PointHazard checkpoint per session (lac-train's layout), for restore/evaluation tests."""
    from lac_rllib.algorithms.lac.config import build_config
    from lac_rllib.train import train

    out = tmp_path_factory.getbasetemp() / "lac_eval_tiny"
    config = build_config("lac/PointHazard-v0", 0, {"env_steps_per_iteration": 500, "replay_capacity": 2000,
                                                     "random_iterations": 1}, timesteps=1500)
    train(config, 1500, str(out), log=lambda *a, **k: None)
    return str(out / "checkpoint")


def chain(critics, obs, mean, log_std, *, nu, noise=None, generator=None, **settings):
    """Algorithm 1 with its settings as keywords (the tests' shorthand for langevin_chain + ChainSettings)."""
    from lac_rllib.algorithms.lac.langevin import ChainSettings, langevin_chain

    return langevin_chain(critics, obs, mean, log_std, nu, ChainSettings(**settings), noise=noise, generator=generator)
