"""SafeAlgorithm's contract with RLlib's private env-runner attributes (docs/dependencies.md,
"Private attributes we rely on"): if RLlib renames them or stops reading them at the initial
reset, the reseed of a restored run silently does nothing, and this fails."""

import inspect

import numpy as np
from conftest import tiny_config
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner


def test_rllib_seeds_the_initial_reset_with_the_private_seed():
    source = inspect.getsource(SingleAgentEnvRunner)
    assert "seed=self._seed if self._needs_initial_reset else None" in source


def test_setting_the_private_seed_reseeds_the_next_reset(ray_session):
    algo = tiny_config(obs_normalization=False, env_steps_per_iteration=50).build_algo()
    try:
        runner = algo.env_runner

        def first_obs(seed: int) -> np.ndarray:
            runner._seed, runner._needs_initial_reset = seed, True
            (episode, *_) = runner.sample(num_timesteps=5, random_actions=True)
            return np.asarray(episode.get_observations(0))

        a, b, c = first_obs(11), first_obs(11), first_obs(12)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)
    finally:
        algo.stop()
