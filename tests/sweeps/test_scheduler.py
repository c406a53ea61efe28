"""Early stopping per configuration (sweeps/scheduler.py): a configuration's seeds are stopped or
kept together, on their mean at a rung, never before the grace period (no Ray: a fake controller)."""

import types

import pytest
from ray.tune.experiment import Trial
from ray.tune.schedulers import TrialScheduler

from sweeps import scheduler as S


class Controller:
    def __init__(self):
        self.trials, self.stopped = [], []

    def get_trials(self):
        return self.trials

    def stop_trial(self, trial):
        trial.status = Trial.TERMINATED
        self.stopped.append(trial.trial_id)


def _setup(seeds=2, grace=1000, max_t=4000):
    sched = S.ConfigurationASHA(time_attr="env_steps", metric="objective", mode="max", max_t=max_t,
                                grace_period=grace, seeds=seeds)
    return sched, Controller()


def _trial(sched, ctl, config, seed):
    t = types.SimpleNamespace(trial_id=f"{config}-s{seed}", status=Trial.RUNNING, config={})
    sched.key[t.trial_id] = config  # the configuration without its seed (configuration_key in a sweep)
    ctl.trials.append(t)
    return t


def _result(sched, ctl, trial, steps, objective):
    return sched.on_trial_result(ctl, trial, {"env_steps": steps, "objective": objective})


def test_rungs_start_at_the_grace_period_and_stay_below_the_budget():
    assert S.milestones(1000, 4000) == [1000]
    assert S.milestones(500, 40_000) == [500, 2000, 8000, 32_000]
    assert S.milestones(5000, 4000) == []


def test_a_configurations_seeds_are_stopped_or_kept_together_on_their_mean():
    sched, ctl = _setup()
    a0, a1, b0, b1 = (_trial(sched, ctl, c, s) for c in ("A", "B") for s in (0, 1))
    # Before the grace period nothing is decided, however bad.
    assert _result(sched, ctl, b0, 500, -1e6) == TrialScheduler.CONTINUE
    # A's first seed at the rung waits for its sibling (paused, and not chosen to run again).
    assert _result(sched, ctl, a0, 1000, 10.0) == TrialScheduler.PAUSE
    a0.status = Trial.PAUSED
    assert sched.choose_trial_to_run(ctl) is None  # a1, b0, b1 are running
    assert _result(sched, ctl, a1, 1000, 12.0) == TrialScheduler.CONTINUE  # the first configuration there
    assert sched.choose_trial_to_run(ctl) is a0  # released, goes on
    # B: one seed above A's mean, the other far below: the mean decides, for both seeds.
    assert _result(sched, ctl, b0, 1000, 20.0) == TrialScheduler.PAUSE
    b0.status = Trial.PAUSED
    assert _result(sched, ctl, b1, 1000, -40.0) == TrialScheduler.STOP
    assert ctl.stopped == [b0.trial_id]  # the waiting sibling is stopped where it waits
    assert sched.recorded[1000] == {"A": 11.0, "B": -10.0}
    # A seed of A that reaches the rung again (a later result) is not judged again.
    assert _result(sched, ctl, a1, 2000, -1e9) == TrialScheduler.CONTINUE


def test_a_good_configuration_is_kept_whole_and_a_failed_seed_is_not_awaited():
    sched, ctl = _setup(seeds=3)
    a = [_trial(sched, ctl, "A", s) for s in range(3)]
    assert [_result(sched, ctl, t, 1000, v) for t, v in zip(a, (1.0, 2.0, 3.0))] == [
        TrialScheduler.PAUSE, TrialScheduler.PAUSE, TrialScheduler.CONTINUE]
    b = [_trial(sched, ctl, "B", s) for s in range(3)]
    assert _result(sched, ctl, b[0], 1000, 5.0) == TrialScheduler.PAUSE
    assert _result(sched, ctl, b[1], 1000, 7.0) == TrialScheduler.PAUSE
    b[2].status = Trial.ERROR
    sched.on_trial_error(ctl, b[2])  # failed for good: B is decided on its two seeds (mean 6 > A's 2)
    assert sched.decisions["B", 1000] == TrialScheduler.CONTINUE and not sched.waiting and not ctl.stopped


@pytest.mark.parametrize("algo,params,timesteps,expected", [
    ("lac", {"random_iterations": 5, "actor_update_start_iteration": 1, "env_steps_per_iteration": 20_000},
     200_000, 120_000),  # (5 + 1) iterations of 20k: longer than a quarter of 200k
    ("sac_lag", {"warmup_env_steps": 200_000}, 500_000, 200_000),
    ("ppo_lag", {"train_batch_size_per_learner": 20_000}, 500_000, 125_000),  # 40k: a quarter is longer
    ("focops", {"train_batch_size_per_learner": 20_000}, 40_000, 40_000),  # its house's warm-up, capped
])
def test_the_grace_period_waits_for_the_multipliers_warm_up(algo, params, timesteps, expected):
    trial = types.SimpleNamespace(algo=algo, params=params)
    assert S.grace_period([trial], timesteps)[0] == expected
    assert S.grace_period([trial], timesteps, override=7)[0] == 7


def test_a_seed_that_ends_past_a_rung_it_never_reported_at_releases_its_waiting_sibling():
    sched, ctl = _setup(grace=1000, max_t=4000)
    a0, a1 = _trial(sched, ctl, "A", 0), _trial(sched, ctl, "A", 1)
    assert _result(sched, ctl, a0, 1000, 3.0) == TrialScheduler.PAUSE
    # a1's one step went from below the rung to the end of its budget: Tune completes it.
    sched.on_trial_complete(ctl, a1, {"env_steps": 4000, "objective": 5.0})
    assert sched.decisions["A", 1000] == TrialScheduler.CONTINUE and not sched.waiting
    assert sched.recorded[1000] == {"A": 4.0}
