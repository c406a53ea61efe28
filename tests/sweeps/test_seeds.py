"""Fresh seeds are fresh in every random stream (sweeps/seeds.py): a confirmation's env, global and
evaluation streams are none of its search's, by RLlib's own seeding rule and by the seeds its env
runners really reset with."""

from pathlib import Path
from types import SimpleNamespace

import pytest

from sweeps import seeds, sweep_file
from sweeps.followup import confirmation_file
from sweeps.tuned import TunedPlan, confirmation_sweep

SEARCH = (0, 1, 2)


def _confirmation_seeds(envs: int, runners: int, count: int = 5) -> dict[str, tuple[int, ...]]:
    """Both confirmation builders' seeds for a search on seeds 0-2 (``envs`` per runner, ``runners``)."""
    text = f"task: lac/PointHazard-v0\nbudget: smoke\nseeds: 3\nset: {{num_envs_per_env_runner: {envs}}}\n"
    sweep = sweep_file.load("x.yaml", text)
    top = [{"group": "top1", "config": "c", "fields": {"beta": 1.0}, "search": {}}]
    plain = confirmation_file(sweep, top, count, "smoke", "x-confirm").seed_list()
    tuned = sweep_file.load("t.yaml", text + f"algo: [lac, ppo_lag]\ntune: {{seeds: 3, confirm_seeds: {count}}}\n")
    search = SimpleNamespace(seeds=SEARCH, sweep=SimpleNamespace(set={}), tasks=("lac/PointHazard-v0",))
    tp = TunedPlan(sweep=tuned, searches={"lac": search, "ppo_lag": search}, registry=Path("registry"))
    return {"confirm": plain, "tuned": confirmation_sweep(tp, {"lac": [top[0]], "ppo_lag": [top[0]]}).seed_list()}


def _rllib_env_seeds(seed: int, runners: int, envs: int) -> set[int]:
    """RLlib 2.60's rule, read from its source: runner w's seed is seed + w (env_runner.py:90-102),
    its first reset passes it to the vector env (single_agent_env_runner.py:799), which resets
    sub-env i with it + i (gymnasium sync_vector_env.py:185-186); the driver's runner (w = 0) has
    envs only without remote runners (single_agent_env_runner.py:98-104)."""
    workers = range(1, runners + 1) if runners else (0,)
    return {seed + w + i for w in workers for i in range(envs)}


def _streams(seed: int, runners: int, envs: int) -> set[int]:
    """Every seed a trial draws from: its envs', its runners' and learner's global seeds (seed + w,
    w = 0..runners) and its evaluation block's (the most episodes a sweep file accepts)."""
    evaluation = range(seeds.eval_seed(seed), seeds.eval_seed(seed) + seeds.EVAL_BLOCK)
    return _rllib_env_seeds(seed, runners, envs) | {seed + w for w in range(runners + 1)} | set(evaluation)


#: (remote env runners, envs per runner): one CPU (the driver samples), and one or two remote runners.
CONFIGS = [(runners, envs) for runners in (0, 1, 2) for envs in (1, 10)]


@pytest.mark.parametrize(("runners", "envs"), CONFIGS)
def test_no_stream_of_a_confirmation_is_one_of_its_search(runners, envs):
    """Also where the confirmation runs on other CPUs than its search did (its runners and envs differ)."""
    # _streams' evaluation block holds the most episodes a sweep file accepts
    with pytest.raises(ValueError, match="eval_episodes"):
        sweep_file.load("x.yaml", f"task: lac/PointHazard-v0\neval_episodes: {seeds.EVAL_BLOCK + 1}\n")
    search = set().union(*(_streams(s, runners, envs) for s in SEARCH))
    for builder, fresh in _confirmation_seeds(envs, runners).items():
        assert len(fresh) == 5 and not set(fresh) & set(SEARCH), builder
        for f in fresh:
            assert seeds.env_seeds(f, runners, envs) == _rllib_env_seeds(f, runners, envs)
            for other in CONFIGS:
                assert not _streams(f, *other) & search, (builder, f, other)
        # and none of one another's: a confirmation's seeds are independent draws
        for a in fresh:
            for b in fresh:
                assert a == b or not _streams(a, runners, envs) & _streams(b, runners, envs)


def test_fresh_seeds_whose_streams_would_meet_the_search_evaluation_seeds_are_refused():
    # seed 2**30 - 10 trains on streams reaching the evaluation seeds of seeds 0 and 1; the fresh seed after it too
    with pytest.raises(ValueError, match="meet the search seeds'"):
        seeds.fresh_seeds((0, 1, 2**30 - 10), 2)
    with pytest.raises(ValueError, match="pass 2147483647"):
        seeds.fresh_seeds((sweep_file.MAX_SEED - 5,), 1)


def test_a_trial_whose_streams_reach_the_stride_is_refused_naming_its_runners_and_envs():
    seeds.check_streams(2, seeds.STRIDE - 2)
    with pytest.raises(ValueError, match=r"num_env_runners 2 \+ num_envs_per_env_runner 999.*<= 1000"):
        seeds.check_streams(2, 999)


def _recorders():
    """What runs in each env runner (defined here: a remote runner's process cannot import this
    module, so cloudpickle ships them by value): one wraps its sub-envs' reset to keep every seed
    given, the other samples a few steps and returns (its global seed, the seeds its envs got)."""
    def install(runner) -> None:
        runner.seen_reset_seeds = []
        for env in (runner.env.unwrapped.envs if runner.env is not None else ()):  # the driver's, beside remote
            base = env.unwrapped                                                  # ones, has no env

            def recorded(*, seed=None, options=None, _reset=base.reset):
                if seed is not None:
                    runner.seen_reset_seeds.append(seed)
                return _reset(seed=seed, options=options)

            base.reset = recorded

    def sampled(runner) -> tuple[int, list[int]]:
        if runner.env is not None:
            runner.sample(num_timesteps=runner.num_envs, random_actions=True)
        return runner._seed, list(runner.seen_reset_seeds)

    return install, sampled


def _reset_seeds(seed: int, runners: int, envs: int = 3) -> tuple[set[int], set[int]]:
    """A tiny LAC of ``seed`` built as a sweep trial builds it: (its env runners' global seeds, the
    seeds its envs really reset with)."""
    from lac_rllib.algorithms.registry import build_config

    config = build_config("lac", "lac/PointHazard-v0", seed, {"num_envs_per_env_runner": envs},
                          num_env_runners=runners, timesteps=1_000)
    algo = config.build_algo()
    install, sampled = _recorders()
    try:
        group = algo.env_runner_group
        group.foreach_env_runner(install, local_env_runner=True)
        out = group.foreach_env_runner(sampled, local_env_runner=True)
    finally:
        algo.stop()
    assert len(out) == runners + 1, out  # every runner answered (RLlib drops a failing one silently)
    return {g for g, _ in out}, {s for _, reset in out for s in reset}


@pytest.mark.parametrize("runners", [0, 1])
def test_the_env_runners_really_reset_a_confirmation_with_seeds_its_search_never_did(ray_session, runners):
    fresh = _confirmation_seeds(3, runners)["confirm"][0]
    search_globals, search_resets = _reset_seeds(max(SEARCH), runners)
    fresh_globals, fresh_resets = _reset_seeds(fresh, runners)
    # the rule the test above computes the streams by
    assert search_resets == _rllib_env_seeds(max(SEARCH), runners, 3) == seeds.env_seeds(max(SEARCH), runners, 3)
    assert fresh_resets == _rllib_env_seeds(fresh, runners, 3)
    assert search_globals == set(range(max(SEARCH), max(SEARCH) + runners + 1))
    assert not (fresh_resets | fresh_globals) & (search_resets | search_globals)
