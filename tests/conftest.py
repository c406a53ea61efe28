"""One Ray start for the whole session (ray.init costs ~10 s and ~1.5 GiB here), and the helpers
several test modules share (``from conftest import ...``)."""

import os

import numpy as np
import pytest

os.environ.setdefault("RAY_DEDUP_LOGS", "0")
# Plans estimate at the rates as measured, whatever machine runs the tests (sweeps/estimate.py;
# tests/sweeps/test_estimate.py turns it on where it is the subject).
os.environ.setdefault("LAC_SWEEP_CALIBRATION", "off")


@pytest.fixture(scope="session")
def ray_session():
    import ray

    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    yield ray
    ray.shutdown()


@pytest.fixture(autouse=True)
def no_denormal_flush_after():
    """A learner built in a test may flush denormals in this process (SAC-Lag's ``flush_denormal``,
    process-wide in torch); the next test starts without, as a fresh process does."""
    yield
    import torch

    torch.set_flush_denormal(False)


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


def learning_run(config, steps: int, tail: int) -> tuple[float, float, float]:
    """Train ``config``'s algorithm until it has sampled ``steps`` env steps (the learning tests'
    runs): the mean episode return and cost of the last ``tail`` iterations (not one noisy one),
    and ν's peak over the run."""
    from lac_rllib.constrained.metrics import ENV_STEPS, EPISODE_COST, EPISODE_RETURN, NU

    algo = config.build_algo()
    history = []
    try:
        while not history or history[-1][ENV_STEPS] < steps:
            r = algo.train()
            history.append({k: float(r[k]) for k in (EPISODE_RETURN, EPISODE_COST, NU, ENV_STEPS)})
    finally:
        algo.stop()
    last = history[-tail:]
    return (float(np.mean([h[EPISODE_RETURN] for h in last])), float(np.mean([h[EPISODE_COST] for h in last])),
            max(h[NU] for h in history))


def random_policy_return(episodes=30, seed=0) -> float:
    """The mean return of uniformly random actions on lac/PointHazard-v0: what a run that learns beats."""
    from lac_rllib.tasks.point_hazard import PointHazardEnv

    env, rng, total = PointHazardEnv(), np.random.default_rng(seed), []
    for i in range(episodes):
        env.reset(seed=seed + i)
        ret, done = 0.0, False
        while not done:
            _, r, term, trunc, _ = env.step(rng.uniform(-1, 1, size=2))
            ret, done = ret + r, term or trunc
        total.append(ret)
    return float(np.mean(total))


def assert_learns_within(run, limit: float, *, nu_peak: float) -> None:
    """A constrained learning run's claims: its tail cost within ``limit``, its tail return clearly
    above a random policy's, and ν risen above ``nu_peak`` on the way (the constraint acted)."""
    ret, cost, nu_max = run
    assert cost <= limit, f"tail episode cost {cost:.2f} above the limit {limit}"
    random_return = random_policy_return()
    assert ret > random_return + 5.0, f"tail return {ret:.2f} not clearly above random {random_return:.2f}"
    assert nu_max > nu_peak, f"ν peaked at {nu_max:.3f}: the constraint never acted"


def assert_learns_unsafely(run, limit: float) -> None:
    """The same run with ν pinned at 0: ν never moved, the tail cost is more than twice ``limit``,
    and it still learns the task (just not safely)."""
    ret, cost, nu_max = run
    assert nu_max == 0.0
    assert cost > 2 * limit, f"with ν pinned at 0 the tail cost {cost:.2f} should be well above the limit {limit}"
    assert ret > random_policy_return() + 5.0


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
    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.train import train

    out = tmp_path_factory.getbasetemp() / "lac_eval_tiny"
    config = LACConfig.build("lac/PointHazard-v0", 0, {"env_steps_per_iteration": 500, "replay_capacity": 2000,
                                                     "random_iterations": 1}, timesteps=1500)
    train(config, 1500, str(out), log=lambda *a, **k: None)
    return str(out / "checkpoint")


def chain(critics, obs, mean, log_std, *, nu, noise=None, generator=None, **settings):
    """Algorithm 1 with its settings as keywords (the tests' shorthand for langevin_chain + ChainSettings)."""
    from lac_rllib.algorithms.lac.langevin import ChainSettings, langevin_chain

    return langevin_chain(critics, obs, mean, log_std, nu, ChainSettings(**settings), noise=noise, generator=generator)
