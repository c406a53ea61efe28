"""The plan a user sees before Ray starts is what the README promises (no Ray: make_plan only)."""

import os
import re
from pathlib import Path

import pytest

from lac_rllib.algorithms.registry import ALGOS, DEFAULT_ALGO, algos_text, budget_fields
from sweeps import estimate
from sweeps import run as cli

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()
FIRST_SCREEN = README.split("---")[0]


def _plan(tmp_path, monkeypatch, *argv):
    monkeypatch.chdir(tmp_path)  # the default MLflow store goes to the working directory
    plan, = cli.make_plan(cli.parse_args(["--storage", str(tmp_path / "ray_results"), *argv]))
    return plan


def test_the_default_ablation_is_what_the_readme_says(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "ablation")
    assert (plan.task, plan.budget, plan.timesteps, plan.n_trials) == ("lac/PointHazard-v0", "quick", 40_000, 24)
    labels = {t.config_label() for t in plan.trials}
    assert labels == {f"lac-NI-langevin_steps={t}-PointHazard-v0" for t in (20, 30)} | {
        f"lac-VT-langevin_steps={t}-PointHazard-v0" for t in (10, 20, 30)} | {
        f"lac-PR-beta={b}-PointHazard-v0" for b in (0.5, 1.0)} | {"lac-unconstrained-PointHazard-v0"}
    unconstrained = [t for t in plan.trials if t.group == "unconstrained"]
    assert [(t.params["nu_lr"], t.params["nu_init"]) for t in unconstrained] == [(0.0, 0.0)] * 3
    defaults = [t.label() for t in plan.trials if t.default]
    assert defaults == [f"lac-VT-langevin_steps=20-PointHazard-v0-s{s}" for s in range(3)]
    # The first screen gives the measured range; the paragraph below it every measurement and the
    # plan's uncalibrated estimate (the tests run uncalibrated: conftest.py), which must be the plan's.
    lo, hi = map(float, re.search(r"\d+ trials, (\d+)-(\d+) min on 2 cores as measured", FIRST_SCREEN).groups())
    assert f"{plan.task}, {plan.n_trials} trials" in FIRST_SCREEN
    measured_text = re.search(r"Measured on .*?the report:", FIRST_SCREEN, re.S).group(0)
    measured = [float(m) for m in re.findall(r"(\d+(?:\.\d+)?) min (?:wall|on)", measured_text)]
    assert len(measured) >= 3 and all(lo <= m <= hi for m in measured), (lo, hi, measured)
    uncalibrated = float(re.search(r"~(\d+) min uncalibrated", measured_text).group(1))
    assert uncalibrated == pytest.approx(plan.estimated_wall_s / 60, rel=0.1), plan.estimated_wall_s / 60
    assert hi <= 35
    assert "quick" in FIRST_SCREEN and "--space ablation" in FIRST_SCREEN


def test_table_3_itself_is_the_paper_budget_and_says_what_it_costs(tmp_path, monkeypatch, capsys):
    args = cli.parse_args(["--space", "ablation", "--task", "SafetyPointGoal1-v0", "--budget", "paper",
                           "--storage", str(tmp_path / "ray_results")])
    monkeypatch.chdir(tmp_path)
    plan, = cli.make_plan(args)
    assert (plan.n_trials, plan.timesteps) == (51, 2_500_000)  # Table 3 and the unconstrained arm
    readme_cpu_h = float(re.search(r"~(\d+)\s+CPU-hours by the plan's estimate", README).group(1))
    assert readme_cpu_h == pytest.approx(plan.estimated_cpu_h, rel=0.15)
    cli.print_plan(plan)
    out = capsys.readouterr().out
    assert f"{plan.estimated_cpu_h:.1f} CPU-hours" in out and "docker/README.md" in out  # points to a cluster


def test_the_estimate_counts_the_chain_length_the_trial_runs(tmp_path, monkeypatch):
    """The Button tasks run T = 50 (their own override, over the preset's and LAC's 30): the plan's
    estimate counts T = 50, and the user's --set wins over the task's own value."""
    steps = 2_500_000
    from lac_rllib.algorithms.lac.config import CHAIN_S_PER_STEP

    chain = CHAIN_S_PER_STEP["safety_gym"] * steps

    step_s = estimate.seconds_per_env_step("SafetyPointButton1-v0", 10)  # the preset's 10 envs per runner

    def formula(t):  # one trial, 1 CPU: the estimate is this trial's, its evaluation block included
        evaluation = 2 * 10 * 1000 * estimate.eval_seconds_per_env_step("SafetyPointButton1-v0")
        return estimate.STARTUP_S + steps * step_s + chain * t + evaluation

    args = ("--space", "paper", "--task", "SafetyPointButton1-v0", "--budget", "paper", "--seeds", "1")
    plan = _plan(tmp_path, monkeypatch, *args)
    (trial,) = plan.trials
    assert trial.params["langevin_steps"] == 50
    assert plan.estimated_wall_s == pytest.approx(formula(50))
    assert formula(50) - formula(30) > 1.5 * 3600  # T = 30 would count ~2 hours less
    assert plan.estimated_cpu_h == pytest.approx(formula(50) / 3600)
    plan = _plan(tmp_path, monkeypatch, *args, "--set", "langevin_steps=70")
    assert plan.trials[0].params["langevin_steps"] == 70
    assert plan.estimated_wall_s == pytest.approx(formula(70))
    # A search is estimated at the fields its trials start from: the task's own T as well.
    plan = _plan(tmp_path, monkeypatch, "--space", "search", "--task", "SafetyPointButton1-v0", "--budget", "paper",
                 "--seeds", "1", "--num-samples", "2", "--max-concurrent", "1")
    assert plan.estimated_wall_s == pytest.approx(2 * formula(50))


def test_trial_fields_are_resolved_once_in_order(tmp_path, monkeypatch):
    """preset < task's own overrides < budget < --set < swept value, in the plan's trials and in a
    search trial (resolved in the trial from what Optuna sampled, by the same function)."""
    from lac_rllib.algorithms.lac.config import PRESETS
    from sweeps import spaces

    plan = _plan(tmp_path, monkeypatch, "--space", "ablation", "--set", "langevin_steps=15", "--set", "beta=2.0")
    by_label = {t.label(): t.params for t in plan.trials}
    assert PRESETS["tiny"]["langevin_steps"] == 10  # the preset ...
    budget = budget_fields(DEFAULT_ALGO, "quick", "tiny")  # what LAC declares for the quick budget on tiny tasks
    assert budget["langevin_steps"] == 20 and budget["num_envs_per_env_runner"] == 10  # ... < the budget ...
    vt10 = by_label["lac-VT-langevin_steps=10-PointHazard-v0-s0"]
    assert (vt10["langevin_steps"], vt10["beta"], vt10["num_envs_per_env_runner"]) == (10, 2.0, 10)  # < swept
    pr = by_label["lac-PR-beta=0.5-PointHazard-v0-s0"]
    assert (pr["langevin_steps"], pr["beta"]) == (15, 0.5)  # --set < swept, budget < --set
    assert pr["replay_capacity"] == PRESETS["tiny"]["replay_capacity"]  # the preset where nothing else sets it
    # No trial runs the defaults any more (T = 15 is not swept), so none is flagged as the baseline.
    assert not any(t.default for t in plan.trials)
    # A search trial: its sampled values over the sweep's budget and --set, default when they change nothing.
    config = {"task": "SafetyPointButton1-v0", "budget": "smoke", "sets": {"beta": 2.0},
              "overrides": {"langevin_steps": 40, "beta": 3.0}, "__trial_index__": 1}
    spec = spaces.trial_spec(config)
    assert spec.seed == 1 and spec.sampled == {"langevin_steps": 40, "beta": 3.0} and not spec.default
    assert spec.params == spaces.trial_params("SafetyPointButton1-v0", "smoke", {}, spec.sampled)
    assert (spec.params["langevin_steps"], spec.params["replay_capacity"]) == (40, 2_000)
    same = spaces.trial_spec({**config, "overrides": {"langevin_steps": 50, "beta": 2.0}})
    assert same.default and same.params["langevin_steps"] == 50  # the task's own T, sampled again


def test_the_compare_space_runs_every_algorithm_at_one_budget(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "compare")
    n = len(ALGOS)  # every algorithm of the package, LAC first
    assert (plan.task, plan.budget, plan.timesteps, plan.n_trials) == ("lac/PointHazard-v0", "quick", 40_000, 3 * n)
    assert [t.algo for t in plan.trials] == [a for a in ALGOS for _ in range(3)] and plan.trials[0].algo == "lac"
    assert [t.params["algo"] for t in plan.trials] == [t.algo for t in plan.trials]
    assert [t.default for t in plan.trials] == [True] * 3 + [False] * (3 * n - 3)  # LAC's defaults: the reference
    assert {t.config_label() for t in plan.trials} == {f"{a}-compare-PointHazard-v0" for a in ALGOS}
    assert "langevin_steps" not in plan.trials[3].params and "langevin_steps" in plan.trials[0].params
    assert plan.estimated_wall_s / 60 <= 35


@pytest.mark.parametrize("argv, needle", [
    (("--space", "compare", "--set", "algo=sac_lag"), "compare.yaml sweeps algo itself"),
    (("--space", "ablation", "--set", "algo=ppo_lag"), "groups.NI.set.langevin_start: a field of lac, not of ppo_lag"),
    (("--space", "paper", "--set", "algo=dqn"), f"unknown algo 'dqn'; accepted: {algos_text()}"),
    (("--space", "compare", "--set", "langevin_steps=5"), "a field of lac, not of ppo_lag"),
])
def test_an_algorithm_a_sweep_cannot_run_is_refused_before_ray(tmp_path, monkeypatch, argv, needle):
    with pytest.raises(ValueError, match=re.escape(needle)):
        _plan(tmp_path, monkeypatch, *argv)


def test_a_baseline_runs_in_the_paper_space_with_its_own_preset(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "paper", "--task", "lac/PointHazard-v0", "--seeds", "1",
                 "--set", "algo=sac_lag")
    (trial,) = plan.trials
    assert trial.algo == "sac_lag" and trial.config_label() == "sac_lag-paper-PointHazard-v0"
    from lac_rllib.algorithms.sac_lag.config import PRESETS

    assert all(trial.params[k] == v for k, v in PRESETS["tiny"].items() if k != "total_env_steps")


def test_ray_address_is_honoured_like_address_with_the_same_cluster_checks(tmp_path, monkeypatch, capsys):
    """``ray job submit`` starts the driver with RAY_ADDRESS set and no --address."""
    import socket

    with socket.socket() as head:
        head.bind(("127.0.0.1", 0))
        head.listen()
        address = f"127.0.0.1:{head.getsockname()[1]}"
        monkeypatch.setenv("RAY_ADDRESS", address)
        with pytest.raises(ValueError, match=r"--tracking-uri sqlite:\S+ with RAY_ADDRESS: each node would write"):
            _plan(tmp_path, monkeypatch, "--space", "smoke")
        monkeypatch.setattr(cli, "check_reachable", lambda uri: None)
        plan = _plan(tmp_path, monkeypatch, "--space", "smoke", "--tracking-uri", "http://mlflow:5000")
        assert (plan.infra.address, plan.infra.address_from) == (address, "RAY_ADDRESS")
        cli.print_plan(plan)
        assert f"cluster {address} from RAY_ADDRESS" in capsys.readouterr().out
        plan = _plan(tmp_path, monkeypatch, "--space", "smoke", "--tracking-uri", "http://mlflow:5000",
                     "--address", address)
        assert plan.infra.address_from == "--address"
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:9")
    with pytest.raises(ValueError, match="RAY_ADDRESS 127.0.0.1:9: cannot connect"):
        _plan(tmp_path, monkeypatch, "--space", "smoke")


def test_a_sweep_ranks_on_its_evaluation_unless_it_runs_none(tmp_path, monkeypatch, capsys):
    assert _plan(tmp_path, monkeypatch, "--space", "ablation").sweep.score == "eval"
    f = tmp_path / "noeval.yaml"
    f.write_text("task: lac/PointHazard-v0\nbudget: smoke\neval_episodes: 0\ngrid: {beta: [0.5, 1.0]}\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(f))
    assert plan.sweep.score == "train"
    cli.print_plan(plan)
    assert "score: train" in capsys.readouterr().out


def test_an_evaluation_mode_no_algorithm_of_the_sweep_has_is_refused_before_ray(tmp_path, monkeypatch):
    f = tmp_path / "modes.yaml"
    f.write_text("task: lac/PointHazard-v0\nbudget: smoke\nalgo: ppo_lag\neval_modes: [generator, langevin]\n")
    with pytest.raises(ValueError, match=r"eval_modes.*'langevin'; accepted with this sweep's algorithms: "
                                         r"generator, stochastic$"):
        _plan(tmp_path, monkeypatch, "--config", str(f))
    f.write_text("task: lac/PointHazard-v0\nbudget: smoke\neval_every: 2\neval_episodes: 0\n")
    with pytest.raises(ValueError, match="eval_every with eval_episodes 0"):
        _plan(tmp_path, monkeypatch, "--config", str(f))


def test_on_a_cluster_the_wall_time_is_estimated_again_at_its_cpus(tmp_path, monkeypatch, capsys):
    from sweeps.sweep import at_cluster_concurrency

    plan = _plan(tmp_path, monkeypatch, "--space", "ablation")
    assert plan.concurrency == min(24, os.cpu_count() or 1) and len(plan.trial_seconds) == 24
    wide = at_cluster_concurrency(plan, 48)  # more CPUs than trials: each trial on its own CPU
    assert wide.concurrency == 24 and wide.estimated_wall_s == pytest.approx(max(plan.trial_seconds))
    narrow = at_cluster_concurrency(plan, 1)
    assert narrow.estimated_wall_s == pytest.approx(sum(plan.trial_seconds))
    assert narrow.estimated_cpu_h == plan.estimated_cpu_h
    assert "cluster: 48 CPUs -> 24 trials at once; estimated wall time ~" in capsys.readouterr().out


def test_a_sweep_under_a_minute_is_planned_in_seconds(tmp_path, monkeypatch, capsys):
    """A smoke sweep of a few tens of seconds used to be planned as "~0 min"."""
    f = tmp_path / "short.yaml"
    f.write_text("task: lac/PointHazard-v0\nbudget: smoke\nseeds: 1\neval_episodes: 0\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(f))
    assert 10 < plan.estimated_wall_s < 59
    cli.print_plan(plan)
    out = capsys.readouterr().out
    assert f"estimated wall time: ~{plan.estimated_wall_s:.0f} s at 1 trials at a time" in out, out
    assert "~0 min" not in out
    # The cluster's line says it the same way; a minute and more reads in minutes, as before.
    from sweeps.sweep import at_cluster_concurrency

    at_cluster_concurrency(plan, 8)
    assert f"estimated wall time ~{plan.estimated_wall_s:.0f} s," in capsys.readouterr().out
    assert [estimate.duration_text(s) for s in (0.4, 40, 59.4, 59.6, 89, 1800)] == [
        "~0 s", "~40 s", "~59 s", "~1 min", "~1 min", "~30 min"]


def test_a_slower_env_is_counted_by_its_step_cost(tmp_path, monkeypatch):
    """A Button1 step costs ~3 Goal1 steps (TaskSpec.step_cost): the env's share of the trial's
    time (training and evaluation) grows by it, the algorithm's update share does not."""
    from lac_rllib.tasks import get_task

    goal, button = get_task("SafetyPointGoal1-v0"), get_task("SafetyPointButton1-v0")
    assert goal.step_cost == 1.0 and button.step_cost > 2.5  # the reference, and a slower task
    assert estimate.seconds_per_env_step(goal.id) == pytest.approx(1 / estimate.RATE["safety_gym"])  # the rate's own
    assert estimate.seconds_per_env_step(button.id) == pytest.approx(estimate.seconds_per_env_step(goal.id) * (
        1 + estimate.ENV_SHARE * (button.step_cost - 1) / (estimate.ENV_SHARE + (1 - estimate.ENV_SHARE) / 10)))
    assert estimate.eval_seconds_per_env_step(button.id) == pytest.approx(
        (1 + estimate.EVAL_ENV_SHARE * (button.step_cost - 1)) / estimate.RATE["safety_gym"])
    f = tmp_path / "s.yaml"

    def wall(task):
        f.write_text(f"task: {task}\nbudget: 40000\nseeds: 1\nalgo: ppo_lag\n")
        return _plan(tmp_path, monkeypatch, "--config", str(f)).estimated_wall_s

    # training at PPO-Lag's 10 envs per runner, then 2 modes x 10 episodes of evaluation
    extra = ((estimate.seconds_per_env_step(button.id, 10) - estimate.seconds_per_env_step(goal.id, 10)) * 40_000
             + (estimate.eval_seconds_per_env_step(button.id) - estimate.eval_seconds_per_env_step(goal.id)) * 20_000)
    assert wall(button.id) - wall(goal.id) == pytest.approx(extra)
    assert extra > 0.5 * (wall(goal.id) - estimate.STARTUP_S)  # a difference a user would see


def test_one_env_per_runner_samples_slower_than_the_presets_ten():
    """The rate holds at the preset's envs per runner; one env (SAC-Lag's, the quick budget's) pays
    the policy's forward and RLlib's per-step work on every step: ~2x slower per step."""
    one, ten = (estimate.seconds_per_env_step("SafetyPointGoal1-v0", n) for n in (1, 10))
    share = estimate.ENV_SHARE
    assert one / ten == pytest.approx(1 / (share + (1 - share) / 10)) and 1.8 < one / ten < 2.6


def test_the_estimate_counts_the_evaluation_blocks(tmp_path, monkeypatch, capsys):
    f = tmp_path / "e.yaml"

    def plan(extra: str):
        f.write_text("task: SafetyPointGoal1-v0\nbudget: 40000\nseeds: 1\nalgo: ppo_lag\n" + extra)
        return _plan(tmp_path, monkeypatch, "--config", str(f))

    none, end, every = plan("eval_episodes: 0\n"), plan(""), plan("eval_every: 1\n")
    assert none.eval_share == 0.0 and 0 < end.eval_share < every.eval_share
    # 2 modes x 10 episodes x 1,000 steps at the preset's rate, once at the end; PPO-Lag's 20k-step
    # iterations at 40k steps: with eval_every 1, 2 more blocks.
    block = 2 * 10 * 1000 * estimate.eval_seconds_per_env_step("SafetyPointGoal1-v0")
    assert end.estimated_wall_s - none.estimated_wall_s == pytest.approx(block)
    assert every.estimated_wall_s - none.estimated_wall_s == pytest.approx(3 * block)
    cli.print_plan(end)
    assert f"~{end.eval_share:.0%} of the estimated time" in capsys.readouterr().out


def test_an_evaluation_episode_is_counted_at_its_tasks_episode_limit(tmp_path, monkeypatch):
    """Circle's episodes are 500 steps (safety_gymnasium's limit), Goal's 1,000: the plan counts
    each evaluation episode at its own task's limit, not at its preset's."""
    f = tmp_path / "e.yaml"

    def eval_s(task: str) -> float:
        walls = []
        for extra in ("eval_episodes: 0\n", ""):
            f.write_text(f"task: {task}\nbudget: 40000\nseeds: 1\nalgo: ppo_lag\n" + extra)
            walls.append(_plan(tmp_path, monkeypatch, "--config", str(f)).estimated_wall_s)
        return (walls[1] - walls[0]) / (2 * 10 * estimate.eval_seconds_per_env_step(task))  # steps per episode

    assert eval_s("SafetyPointCircle1-v0") == pytest.approx(500)
    assert eval_s("SafetyPointGoal1-v0") == pytest.approx(1000)


def test_a_command_plans_a_list_of_jobs_each_checked_then_run_the_same_way(tmp_path, monkeypatch):
    """make_plan returns one type, a list of jobs (a sweep's Plan, a tuned comparison's TunedPlan per
    task): main checks each before Ray starts and runs each through run_plan, whichever it is."""
    from sweeps.tuned import TunedPlan

    monkeypatch.chdir(tmp_path)
    ran = []
    monkeypatch.setattr(cli, "run_locked", lambda plan, sweep_dir: ran.append((plan.name, sweep_dir)) or 0)
    argv = ["--space", "smoke", "--budget", "smoke", "--seeds", "1", "--storage", str(tmp_path / "rr")]
    jobs = cli.make_plan(cli.parse_args(argv))
    assert [type(j).__name__ for j in jobs] == ["Plan"]
    assert cli.main(argv) == 0 and ran == [(jobs[0].name, Path(jobs[0].storage) / jobs[0].name)]
    tuned = cli.make_plan(cli.parse_args(["--space", "table1", "--budget", "smoke", "--tune", "2", "--storage",
                                          str(tmp_path / "rr")]))
    assert len(tuned) == 4 and all(isinstance(j, TunedPlan) for j in tuned)
    for job in tuned:
        job.check()  # no search ran yet: every directory is free


def test_the_plan_says_which_backend_each_task_steps_on(tmp_path, monkeypatch, capsys):
    (tmp_path / "b.yaml").write_text("task: [SafetyPointGoal1-v0, SafetyDoggoGoal1-v0]\nalgo: ppo_lag\nbudget: smoke\n"
                                     "seeds: 1\ngroups:\n  g: {grid: {env_backend: [batched, stock]}}\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(tmp_path / "b.yaml"))
    assert cli.env_backends(plan) == ("SafetyPointGoal1-v0 batched and stock; SafetyDoggoGoal1-v0 stock "
                                      "(no batched one)")
    cli.print_plan(plan)
    assert "env backend: SafetyPointGoal1-v0 batched and stock" in capsys.readouterr().out
    assert cli.env_backends(_plan(tmp_path, monkeypatch, "--space", "ablation", "--name", "a2")) == ""


def test_a_sweep_file_sets_a_limit_per_constraint_and_bad_ones_are_refused_before_ray(tmp_path, monkeypatch):
    """``constraints:`` reaches every trial's ``constraints`` field (each algorithm), ``--set
    constraints.NAME=b`` changes one limit and keeps the others; a name the task lacks, a negative
    limit, and constraints with cost_limit or a ladder are refused before Ray, each in one line."""
    sweep = tmp_path / "two.yaml"
    sweep.write_text("task: lac/PointTwoCosts-v0\nalgo: [lac, cpo]\nbudget: smoke\nseeds: 1\n"
                     "constraints: {hazard: 2, lane: 10}\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(sweep), "--set", "constraints.lane=7")
    assert {t.algo for t in plan.trials} == {"lac", "cpo"}
    assert all(t.params["constraints"] == {"hazard": 2.0, "lane": 7.0} for t in plan.trials)
    for argv, needle in ((("--set", "constraints.pillars=3"), r"has no constraint 'pillars'; accepted: hazard, lane"),
                         (("--set", "constraints.lane=-1"), r"--set constraints: Input should be greater than"),
                         (("--set", "cost_limit=3"), r"constraints with cost_limit: .*accepted: constraints alone"),
                         (("--cost-limits", "1,2"), r"constraints with cost_limits")):
        with pytest.raises(ValueError, match=needle) as err:
            _plan(tmp_path, monkeypatch, "--config", str(sweep), *argv)
        assert "\n" not in str(err.value)


def test_a_ladder_along_one_constraint_keeps_the_others_at_their_limits(tmp_path, monkeypatch):
    sweep = tmp_path / "ladder.yaml"
    sweep.write_text("task: lac/PointTwoCosts-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\n"
                     "constraints: {hazard: 2, lane: 10}\ncost_limits: [5, 20]\nladder_constraint: lane\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(sweep))
    assert [(t.limit, t.params["constraints"]) for t in plan.trials] == [
        (5.0, {"hazard": 2.0, "lane": 5.0}), (20.0, {"hazard": 2.0, "lane": 20.0})]
    assert all(t.params["cost_limit"] is None for t in plan.trials)
    bare = tmp_path / "bare.yaml"
    bare.write_text("task: lac/PointTwoCosts-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\ncost_limits: [5, 20]\n"
                    "ladder_constraint: lane\n")
    with pytest.raises(ValueError, match=r"ladder_constraint lane without constraints; accepted: with constraints"):
        _plan(tmp_path, monkeypatch, "--config", str(bare))


def test_a_frontier_along_one_constraint_holds_its_multiplier_and_lets_the_others_learn(tmp_path, monkeypatch):
    sweep = tmp_path / "along.yaml"
    sweep.write_text("task: lac/PointTwoCosts-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\n"
                     "constraints: {hazard: 2}\ncost_limits: [5, 20]\nladder_constraint: lane\n"
                     "frontier: {algo: ppo_lag, nu: [0.0, 1.0]}\n")
    plan = _plan(tmp_path, monkeypatch, "--config", str(sweep))
    front = [t.params for t in plan.trials if t.group == "frontier"]
    assert [(p["nu_fixed"], p["nu_fixed_constraint"]) for p in front] == [(0.0, "lane"), (1.0, "lane")]
    assert all(p["constraints"] == {"hazard": 2.0, "lane": 20.0} for p in front)
    rungs = [t.params["constraints"] for t in plan.trials if t.group != "frontier"]
    assert rungs == [{"hazard": 2.0, "lane": 5.0}, {"hazard": 2.0, "lane": 20.0}]


def test_a_users_env_in_a_sweep_file_declares_its_constraints(tmp_path, monkeypatch):
    """``task: {factory: ..., constraints: {name: info_key}}``: a sweep's ``constraints`` gives that
    name a limit; a declared key its info lacks is refused before Ray, named with the keys it has."""
    import shutil
    import sys

    monkeypatch.setattr(sys, "path", list(sys.path))
    shutil.copy(Path(__file__).parent / "user_envs.py", tmp_path / "user_envs.py")
    env = "{factory: 'user_envs:make_safe', cost_limit: 5, cost_key: violation, preset: tiny, name: mine/Line-v0"
    sweep = tmp_path / "mine.yaml"
    sweep.write_text(f"task: {env}, constraints: {{right: violation}}}}\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\n"
                     "constraints: {right: 3}\n")
    (trial,) = _plan(tmp_path, monkeypatch, "--config", str(sweep)).trials
    assert trial.params["constraints"] == {"right": 3.0}
    sweep.write_text(f"task: {env}, constraints: {{right: speed}}}}\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\n")
    with pytest.raises(ValueError, match=r"no 'speed', the key of constraint 'right' \(keys: \['violation'\]\)"):
        _plan(tmp_path, monkeypatch, "--config", str(sweep), "--name", "x2")
