"""The sweep service end to end, checked through MLflow's client (and Optuna's study)."""

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from lac_rllib.algorithms.registry import ALGOS
from lac_rllib.constrained.metrics import CHAIN_HEALTH_KEYS
from sweeps import run as cli
from sweeps.objective import objective
from sweeps.sweep import ConstrainedOptunaSearch, run_sweep, search_algorithm
from sweeps.sweep_file import MULTI_OBJECTIVE, SEARCHERS

REPO = Path(__file__).resolve().parents[2]


def _args(tmp_path, *extra):
    return cli.parse_args(["--space", "smoke", "--budget", "smoke", "--seeds", "2", "--max-concurrent", "2",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                           "--storage", str(tmp_path / "ray_results"), "--experiment", "test", *extra])


def _runs(tmp_path):
    client = MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    exp = client.get_experiment_by_name("test")
    runs = client.search_runs([exp.experiment_id], max_results=1000)
    parents = [r for r in runs if r.data.tags.get("lac.sweep") == "1"]
    children = [r for r in runs if "mlflow.parentRunId" in r.data.tags]
    return client, parents, children


def _sweep(tmp_path, args, mutate=None):
    plan, = cli.make_plan(args)
    if mutate:
        plan = dataclasses.replace(plan, trials=mutate(plan.trials))
    return run_sweep(plan, Path(plan.storage) / plan.name, "test-commit")


@pytest.mark.slow
def test_smoke_sweep_end_to_end(ray_session, tmp_path, capsys):
    assert _sweep(tmp_path, _args(tmp_path, "--set", "obs_std_floor=0.05")) == 0
    out = capsys.readouterr().out
    client, parents, children = _runs(tmp_path)
    assert len(parents) == 1 and len(children) == 4
    parent = parents[0]
    assert parent.info.status == "FINISHED"
    # MLflow opens on the results: model-training kind, direct links (printed at start and end), the note.
    exp = client.get_experiment_by_name("test")
    assert exp.tags["mlflow.experimentKind"] == "custom_model_development"
    links = (f"http://127.0.0.1:5000/#/experiments/{exp.experiment_id}/runs?workflowType=machine_learning",
             f"http://127.0.0.1:5000/#/experiments/{exp.experiment_id}/runs/{parent.info.run_id}"
             "?workflowType=machine_learning")
    assert all(out.count(link) == 2 for link in links), out[-3000:]
    note = parent.data.tags["mlflow.note.content"]
    assert note.startswith("**Sweep `smoke-PointHazard-v0-smoke`**: 4 of 4 trials finished"), note
    assert "| smoke | langevin_steps=5 | 2 |" in note and "| smoke | langevin_steps=10 (default) | 2 |" in note, note
    assert sorted(c.data.tags["mlflow.runName"] for c in children) == [
        f"lac-smoke-langevin_steps={v}-PointHazard-v0-s{s}" for v in (10, 5) for s in (0, 1)]
    # The live table: what each trial is, its figures, and a progress line.
    headers = ("status", "iter", "env steps", "return", "cost", "feasible", "ν")
    assert "trial  " in out and all(h in out for h in headers)
    assert re.search(r"lac-smoke-langevin_steps=5-PointHazard-v0-s1 +TERMINATED +4 +2,000 ", out), out[-3000:]
    assert "progress: 4/4 trials done · 0 running · ETA ~0 min (mean" in out, out[-3000:]
    assert "...iteration" not in out
    assert {"ray", "torch", "mujoco", "numpy", "git_commit", "space", "seeds"} <= set(parent.data.params)
    assert parent.data.params["task"] == "lac/PointHazard-v0"  # resolved, not the CLI's None
    # Every trial ended with its evaluation block: 10 episodes per mode on its own seeds, and its score.
    for c in children:
        m, tags = c.data.metrics, c.data.tags
        assert {f"eval/{mode}/{k}" for mode in ("generator", "stochastic")
                for k in ("return_mean", "cost_mean", "within_limit_fraction")} <= set(m), sorted(m)
        assert tags["lac.eval.generator.episodes"] == tags["lac.eval.stochastic.episodes"] == "10"
        assert "lac.eval_error" not in tags and m["eval_time_s"] > 0 and "score_return" in m
        # Ranked on the evaluation (score: eval, the default), the training score logged beside it.
        assert tags["lac.score"] == "eval" and m["score_return"] == m["eval/generator/return_mean"]
        assert m["score_cost"] == m["eval/generator/cost_mean"] and "train_cost" in m
    assert "Scores: each trial's score is its evaluation block's" in note, note
    summary = {a.path for a in client.list_artifacts(parent.info.run_id, "summary")}
    assert {"summary/summary.csv", "summary/summary.md", "summary/best.json", "summary/cost_boxplots.png",
            "summary/learning_curves.png", "summary/aggregates.png"} <= summary
    assert "plan.json" in {a.path for a in client.list_artifacts(parent.info.run_id)}
    assert sorted(json.loads(c.data.params["langevin_steps"]) for c in children) == [5, 5, 10, 10]
    for c in children:
        assert c.info.status == "FINISHED" and c.data.tags["mlflow.parentRunId"] == parent.info.run_id
        assert {"task", "seed", "temperature", "beta", "langevin_start", "swept_param"} <= set(c.data.params)
        assert float(c.data.params["obs_std_floor"]) == 0.05  # --set reaches every trial
        assert c.data.tags.get("lac.node_id")
        # what the tiny preset's float32 chain ran as (a rule like "auto" would say what it resolved to)
        assert c.data.tags["lac.resolved.langevin_dtype"] == "float32"
        hist = client.get_metric_history(c.info.run_id, "episode_cost")
        assert [m.step for m in hist] == [500, 1000, 1500, 2000]
        for key in ("episode_return", "cost_limit", "nu", "critic_loss", "actor_loss", "env_steps", "wall_time_s",
                    *CHAIN_HEALTH_KEYS, "nu_max", "target_reward_mean", "target_cost_mean"):
            assert len(client.get_metric_history(c.info.run_id, key)) == 4, key
        at_bound = client.get_metric_history(c.info.run_id, "langevin_at_bound")
        assert all(0.0 <= m.value <= 1.0 for m in at_bound)
        arts = {a.path for a in client.list_artifacts(c.info.run_id)}
        assert {"checkpoint", "config.json", "learning_curve.png"} <= arts
        assert client.list_artifacts(c.info.run_id, "checkpoint"), "checkpoint directory is empty"
        assert "rllib_checkpoint.json" in json.loads(c.data.tags["lac.checkpoint_sha256"])  # the manifest


@pytest.mark.slow
def test_a_failing_trial_does_not_stop_the_others(ray_session, tmp_path):
    args = _args(tmp_path, "--max-failures", "0", "--seeds", "1")
    fail_first = lambda trials: [dataclasses.replace(trials[0], fail_at_iteration=2), *trials[1:]]  # noqa: E731
    assert _sweep(tmp_path, args, fail_first) == 0
    client, parents, children = _runs(tmp_path)
    status = {json.loads(c.data.params["langevin_steps"]): c for c in children}
    assert status[5].info.status == "FAILED" and "injected failure" in status[5].data.tags["lac.error"]
    assert len(client.get_metric_history(status[5].info.run_id, "episode_return")) == 1  # kept
    assert status[10].info.status == "FINISHED"
    assert parents[0].data.tags["lac.failed_trials"] == "1"


@pytest.mark.slow
def test_search_scores_each_configuration_over_its_seeds(ray_session, tmp_path):
    args = cli.parse_args(["--space", "search", "--task", "lac/PointHazard-v0", "--budget", "smoke",
                           "--num-samples", "3", "--seeds", "2", "--max-concurrent", "2",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                           "--storage", str(tmp_path / "ray_results"), "--experiment", "test"])
    assert _sweep(tmp_path, args) == 0
    _, parents, children = _runs(tmp_path)
    assert len(children) == 6 and all(c.info.status == "FINISHED" for c in children)
    by_config = {}
    for c in children:
        by_config.setdefault(c.data.tags["lac.config_id"], []).append(c)
    assert len(by_config) == 3, "lac.config_id: one per Optuna sample, shared by its seeds"
    for runs in by_config.values():
        assert sorted(json.loads(r.data.params["seed"]) for r in runs) == [0, 1]
        assert len({r.data.params["temperature"] for r in runs}) == 1  # the same sample
        labels = {r.data.tags["lac.config"] for r in runs}
        assert len(labels) == 1 and labels.pop().startswith("lac-search-T=")
    # Optuna was told once per configuration: the objective and the constraint of the seed means.
    searcher = ConstrainedOptunaSearch()
    searcher.restore_from_dir(str(tmp_path / "ray_results" / "search-PointHazard-v0-smoke"))
    study = searcher._ot_study
    assert len(study.trials) == 3
    expected = {}
    for runs in by_config.values():
        m = [r.data.metrics for r in runs]
        # Each seed's declared score (score: eval, sweeps/score.py), as the trial reported it to Tune.
        ret, cost = (sum(x[k] for x in m) / 2 for k in ("score_return", "score_cost"))
        limit = m[0]["cost_limit"]
        t = json.loads(runs[0].data.params["langevin_steps"])
        expected[t] = (round(objective(ret, cost, limit), 6), round(cost - limit, 6))
    def constraint(t):
        attrs = t.system_attrs
        return attrs["constraints:episode_cost_minus_limit"] if "constraints:episode_cost_minus_limit" in attrs \
            else attrs["constraints"][0]

    got = {t.params.get("overrides/langevin_steps", t.params.get("langevin_steps")):
           (round(t.value, 6), round(constraint(t), 6)) for t in study.trials}
    assert got == expected
    note = parents[0].data.tags["mlflow.note.content"]
    assert "over 2 seeds per configuration" in note and "Warning: fewer than 5 seeds" in note


def _cli(tmp_path, *extra, **kw):
    cmd = [sys.executable, str(REPO / "sweeps" / "run.py"), "--space", "smoke", "--budget", "smoke", "--seeds", "2",
           "--max-concurrent", "1", "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
           "--storage", str(tmp_path / "ray_results"), "--experiment", "test", *extra]
    return subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)


def _wait_for_children(tmp_path, ready, timeout=300, name="smoke-PointHazard-v0-smoke") -> list:
    """Poll the running smoke sweep's child runs until ``ready(children)``; return them."""
    deadline, children = time.time() + timeout, []
    while time.time() < deadline:
        time.sleep(2)
        # sweep.json is written after the parent run exists: polling earlier could race the
        # driver creating MLflow's tables.
        if (tmp_path / "ray_results" / name / "sweep.json").exists():
            try:
                _, _, children = _runs(tmp_path)
            except Exception:  # the store may be mid-creation
                continue
            if ready(children):
                break
    return children


@pytest.mark.slow
def test_resume_after_driver_sigkill(tmp_path):
    proc = _cli(tmp_path, start_new_session=True)
    try:  # one finished trial and one started after it
        children = _wait_for_children(
            tmp_path, lambda cs: len(cs) >= 2 and any(c.info.status == "FINISHED" for c in cs))
        finished = [c for c in children if c.info.status == "FINISHED"]
        assert finished, "no trial finished before the deadline"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the driver and everything it started
        proc.wait()
    before = {c.data.tags["lac.trial_id"]: c.info.end_time for c in finished}

    resumed = _cli(tmp_path, "--resume")
    out, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, out[-3000:]
    client, parents, children = _runs(tmp_path)
    assert len(parents) == 1
    ids = [c.data.tags["lac.trial_id"] for c in children]
    assert len(children) == 4 and len(set(ids)) == 4, "one MLflow run per trial"
    assert all(c.info.status == "FINISHED" for c in children)
    for c in children:
        if c.data.tags["lac.trial_id"] in before:  # finished before the kill: not run again
            assert c.info.end_time == before[c.data.tags["lac.trial_id"]]
        steps = [m.step for m in client.get_metric_history(c.info.run_id, "env_steps")]
        assert steps[-1] == 2000 and steps == sorted(steps)


@pytest.mark.slow
def test_sigint_stops_cleanly_and_resume_completes_the_rest(tmp_path):
    proc = _cli(tmp_path, start_new_session=True)
    try:  # one trial finished and the next one running
        _wait_for_children(tmp_path, lambda cs: any(c.info.status == "FINISHED" for c in cs)
                           and any(c.info.status == "RUNNING" for c in cs))
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        out, _ = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, out[-3000:]
    match = re.search(r"interrupted: (\d) of 4 trials finished.*resume with --resume", out)
    assert match and int(match.group(1)) < 4, out[-3000:]
    assert "sweep done" not in out
    _, parents, children = _runs(tmp_path)
    assert parents[0].info.status == "KILLED" and parents[0].data.tags["lac.sweep_status"] == "interrupted"
    assert children and not [c for c in children if c.info.status == "RUNNING"], "no child run left RUNNING"

    resumed = _cli(tmp_path, "--resume")
    out, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, out[-3000:]
    client, parents, children = _runs(tmp_path)
    assert parents[0].info.status == "FINISHED" and parents[0].data.tags["lac.sweep_status"] == "finished"
    ids = [c.data.tags["lac.trial_id"] for c in children]
    assert len(children) == 4 and len(set(ids)) == 4 and all(c.info.status == "FINISHED" for c in children)
    for c in children:
        steps = [m.step for m in client.get_metric_history(c.info.run_id, "env_steps")]
        assert steps == sorted(set(steps)) and steps[-1] == 2000, steps  # no duplicate metric steps


@pytest.mark.slow
def test_a_resumed_search_continues_its_optuna_study(tmp_path):
    import optuna

    name, storage = "search-PointHazard-v0-smoke", f"sqlite:///{tmp_path / 'optuna.db'}"
    search = ("--space", "search", "--task", "lac/PointHazard-v0", "--num-samples", "3", "--seeds", "1")
    proc = _cli(tmp_path, *search, start_new_session=True)
    try:  # one sample finished, the next one running
        _wait_for_children(tmp_path, lambda cs: any(c.info.status == "FINISHED" for c in cs)
                           and any(c.info.status == "RUNNING" for c in cs), name=name)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, out[-3000:]
    assert f"Optuna study '{name}': {storage}  (optuna-dashboard {storage})" in out  # the plan says where
    (before,) = optuna.get_all_study_summaries(storage)
    assert before.study_name == name and 1 <= before.n_trials < 3

    resumed = _cli(tmp_path, *search, "--resume")
    out, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, out[-3000:]
    (after,) = optuna.get_all_study_summaries(storage)  # the same study, no second one
    assert after.study_name == name and after._study_id == before._study_id
    study = optuna.load_study(study_name=name, storage=storage)
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(study.trials) == len(done) == 3, [t.state for t in study.trials]
    _, _, children = _runs(tmp_path)
    assert sorted(round(t.value, 6) for t in done) == sorted(round(c.data.metrics["objective"], 6) for c in children)


def test_a_fresh_search_does_not_adopt_an_existing_study(tmp_path):
    import optuna

    optuna.create_study(study_name="search-PointHazard-v0-smoke", storage=f"sqlite:///{tmp_path / 'optuna.db'}")
    args = cli.parse_args(["--space", "search", "--task", "lac/PointHazard-v0", "--budget", "smoke",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")])
    with pytest.raises(ValueError, match="an Optuna study named 'search-PointHazard-v0-smoke' exists in sqlite:///"):
        cli.make_plan(args)  # before Ray: main() prints it and exits 2, like every bad input
    assert not (tmp_path / "rr" / "search-PointHazard-v0-smoke").exists()


@pytest.mark.parametrize("extra,needle", [
    (["--space", "nope"], "invalid choice: 'nope'"),
    (["--task", "Nope-v0"], "unknown task 'Nope-v0'; closest known tasks:"),
    (["--budget", "huge"], "argument --budget: 'huge' is invalid; accepted: smoke | quick | paper or env steps"),
    (["--seeds", "0"], "argument --seeds: 0 is invalid; accepted: an integer >= 1"),
    (["--tracking-uri", "http://127.0.0.1:9"], "--tracking-uri http://127.0.0.1:9 is unreachable"),
    (["--address", "127.0.0.1:9"], "--address 127.0.0.1:9: cannot connect"),
    (["--address", "not an address"], "accepted: auto, HOST:PORT"),
    (["--set", "nu_max_adaptive=2"], "nu_max_adaptive=2 is invalid; accepted: True | False"),
    (["--cpus-per-trial", "4096"], "--cpus-per-trial 4096 is more than this machine's"),
    (["--storage", "s3://bucket/sweeps"], "--storage s3://bucket/sweeps: object stores are not supported"),
    (["--storage", "/proc/x/tune"], "--storage /proc/x/tune is not a writable directory"),
    (["--set", "no_such_field=1"], "--set no_such_field: unknown lac field 'no_such_field'"),
])
def test_bad_inputs_fail_before_ray(tmp_path, extra, needle, monkeypatch, capsys):
    _check_bad_input(tmp_path, extra, needle, monkeypatch, capsys)


def _check_bad_input(tmp_path, extra, needle, monkeypatch, capsys):
    """The CLI's main() in this process (a subprocess per case cost ~8 s of imports each): exit
    code 2, the message, and neither Ray nor a sweep directory started."""
    import ray

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(ray, "init", lambda *a, **k: pytest.fail("Ray was started for a bad input"))
    try:
        rc = cli.main(["--space", "smoke", *extra])
    except SystemExit as e:  # argparse's own errors
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2 and all(n in err for n in ((needle,) if isinstance(needle, str) else needle)), err
    assert "--resume" in extra or not (tmp_path / "ray_results").exists()


def test_a_bad_input_fails_before_ray_as_a_command(tmp_path):
    cmd = [sys.executable, str(REPO / "sweeps" / "run.py"), "--space", "smoke", "--set", "no_such_field=1"]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--set no_such_field: unknown lac field 'no_such_field'" in proc.stderr
    assert "Started a local Ray instance" not in proc.stdout + proc.stderr
    assert not (tmp_path / "ray_results").exists()


def test_a_nan_constraint_does_not_kill_the_searcher():
    """episode_cost is NaN until an episode completes after a (re)start; Optuna refuses NaN
    constraints, and the error used to escape from inside Tune's controller."""
    import math

    import optuna
    from ray import tune

    searcher = ConstrainedOptunaSearch(space={"x": tune.uniform(0.0, 1.0)}, metric="objective", mode="max",
                                       sampler=optuna.samplers.TPESampler(seed=0))
    searcher.suggest("nan")
    searcher.suggest("finite")
    searcher.on_trial_complete("nan", {"objective": -2e6, "constraint": math.nan})
    searcher.on_trial_complete("finite", {"objective": 1.5, "constraint": -3.0})
    nan_trial, finite_trial = searcher._ot_study.trials
    assert nan_trial.state == finite_trial.state == optuna.trial.TrialState.COMPLETE
    key = "constraints:episode_cost_minus_limit"  # where Optuna 5's set_constraint stores it
    assert nan_trial.value == -2e6 and not any(k.startswith("constraints") for k in nan_trial.system_attrs)
    assert finite_trial.system_attrs[key] == -3.0


def test_a_trial_larger_than_any_node_fails_before_tune(ray_session, tmp_path, capsys):
    # The session's Ray has 2 CPUs (as a cluster reached with --address could have): a 3-CPU trial
    # would wait in PENDING forever.
    plan, = cli.make_plan(_args(tmp_path))
    plan = dataclasses.replace(plan, sweep=plan.sweep.model_copy(update={"cpus_per_trial": 3}))
    assert run_sweep(plan, Path(plan.storage) / plan.name, "test-commit") == 2
    assert "--cpus-per-trial 3 is more than the largest node of the Ray cluster has (2 CPUs)" in capsys.readouterr().err
    assert not (tmp_path / "mlflow.db").exists() or not _runs(tmp_path)[1], "no parent run for a sweep that never ran"


@pytest.mark.parametrize("changed,needle", [
    (["--experiment", "other"], "experiment='test' (now 'other')"),
    (["--seeds", "3"], "seeds={'count': 2, 'start': 0} (now {'count': 3, 'start': 0})"),
    (["--set", "obs_clip=4.0"], "set={} (now {'obs_clip': 4.0})"),
    (["--optuna-seed", "3"], "--optuna-seed=0 (now 3)"),
    (["--tracking-uri", "sqlite:///elsewhere.db"], "tracking_uri="),
])
def test_resume_with_other_settings_is_refused(tmp_path, changed, needle, monkeypatch, capsys):
    from sweeps.record import write_record

    plan, = cli.make_plan(_args(tmp_path))
    write_record(Path(plan.storage) / plan.name, plan, "parent-run")
    base = ["--space", "smoke", "--budget", "smoke", "--seeds", "2", "--experiment", "test",
            "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "ray_results")]
    _check_bad_input(tmp_path, [*base, *changed, "--resume"], ("was started with other settings", needle),
                     monkeypatch, capsys)


@pytest.mark.slow
def test_a_sweep_that_failed_to_start_can_be_resumed(ray_session, tmp_path, monkeypatch):
    import sweeps.sweep as sweep_mod

    args = _args(tmp_path)
    plan, = cli.make_plan(args)
    sweep_dir = Path(plan.storage) / plan.name

    def broken(*a, **k):
        raise RuntimeError("Tuner could not be built")

    with monkeypatch.context() as m:
        m.setattr(sweep_mod, "_tuner", broken)
        with pytest.raises(RuntimeError, match="could not be built"):
            run_sweep(plan, sweep_dir, "test-commit")
    _, parents, _ = _runs(tmp_path)
    assert parents[0].info.status == "FAILED" and parents[0].data.tags["lac.sweep_status"] == "failed to start"
    assert (sweep_dir / "sweep.json").exists()  # resumable: not "exists" and "no sweep" at once
    args.resume = True
    assert run_sweep(cli.make_plan(args)[0], sweep_dir, "test-commit") == 0
    _, parents, children = _runs(tmp_path)
    assert len(parents) == 1 and parents[0].info.status == "FINISHED"  # the same parent run, completed
    assert len(children) == 4 and all(c.info.status == "FINISHED" for c in children)


@pytest.mark.slow
def test_asha_stops_a_configurations_seeds_together_after_the_grace_period(ray_session, tmp_path, capsys):
    """Two configurations of 2 seeds, one of them certain to score low (a cost limit of 0: every
    seed with a cost is infeasible), 2 trials at a time: its seeds stop together at the first rung,
    which waits for the multiplier's warm-up; the other configuration's run to the end."""
    import pandas as pd

    f = tmp_path / "asha.yaml"
    f.write_text("task: lac/PointHazard-v0\nbudget: smoke\nseeds: 2\nscheduler: asha\neval_episodes: 2\n"
                 "eval_every: 2\neval_modes: [generator, langevin]\ngrid: {cost_limit: [1000.0, 0.0]}\n")
    args = cli.parse_args(["--config", str(f), "--max-concurrent", "2", "--tracking-uri",
                           f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "ray_results"),
                           "--experiment", "test"])
    plan, = cli.make_plan(args)
    grace, why, rungs = plan.early_stopping
    # LAC's smoke warm-up: (1 random iteration + 1) × 500 env steps, longer than a quarter of 2,000.
    assert (grace, rungs) == (1000, (1000,)) and "lac's multiplier warm-up" in why, plan.early_stopping
    assert run_sweep(plan, Path(plan.storage) / plan.name, "test-commit") == 0
    client, parents, children = _runs(tmp_path)
    assert len(children) == 4 and not [c for c in children if c.info.status != "FINISHED"], "every run closed"
    last = {c.info.run_id: client.get_metric_history(c.info.run_id, "env_steps")[-1].step for c in children}
    by_config = {}
    for c in children:
        by_config.setdefault(float(c.data.params["cost_limit"]), []).append(c)
    low, high = by_config[0.0], by_config[1000.0]
    assert [last[c.info.run_id] for c in low] == [1000, 1000], "both seeds stopped at the rung, none before"
    assert all(c.data.tags.get("lac.stopped_early") == "1" for c in low)
    assert [last[c.info.run_id] for c in high] == [2000, 2000]
    assert not any(c.data.tags.get("lac.stopped_early") for c in high)
    # The evaluation block every 2 iterations (an evaluation curve), in the modes the file asks.
    for c in children:
        for mode in ("generator", "langevin"):
            steps = [m.step for m in client.get_metric_history(c.info.run_id, f"eval/{mode}/return_mean")]
            assert steps == [1000, 2000][:len(steps)] and len(steps) == (1 if c in low else 2), (mode, steps)
        assert "eval/stochastic/return_mean" not in c.data.metrics
    assert "Evaluation blocks:" in parents[0].data.tags["mlflow.note.content"]
    trials = pd.read_csv(client.download_artifacts(parents[0].info.run_id, "summary/trials.csv", str(tmp_path)))
    assert "ERROR" not in set(trials["status"]) and (trials["status"] == "STOPPED").sum() == 2
    summary = pd.read_csv(client.download_artifacts(parents[0].info.run_id, "summary/summary.csv", str(tmp_path)))
    assert summary["n_stopped"].sum() == 2 and summary["n_failed"].sum() == 0


@pytest.mark.parametrize("extra,needle", [
    ([], "with --address: each node would write its own local store"),  # the default sqlite store
    (["--tracking-uri", "http://127.0.0.1:{port}", "--storage", "relative/dir"],
     "--storage relative/dir with --address: a relative path is a different directory on every node"),
])
def test_cluster_inputs_must_be_shared(tmp_path, extra, needle, monkeypatch, capsys):
    import socket

    with socket.socket() as server:  # something listening, so --address passes its reachability check
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        _check_bad_input(tmp_path, ["--address", f"127.0.0.1:{port}", *[x.format(port=port) for x in extra]], needle,
                         monkeypatch, capsys)


@pytest.mark.slow
def test_a_two_cpu_trial_samples_with_two_env_runners(ray_session, tmp_path):
    """--cpus-per-trial 2: the trial's placement group holds RLlib's bundles (the driver, one per env
    runner) within the session's 2 CPUs, and the trial finishes; a split that does not divide the
    envs is refused before Ray starts."""
    with pytest.raises(ValueError, match="--cpus-per-trial 2 is invalid with num_envs_per_env_runner=1"):
        cli.make_plan(_args(tmp_path, "--cpus-per-trial", "2"))
    args = _args(tmp_path, "--cpus-per-trial", "2", "--set", "num_envs_per_env_runner=2", "--max-concurrent", "1",
                 "--seeds", "1")
    assert _sweep(tmp_path, args) == 0
    _, _, children = _runs(tmp_path)
    assert len(children) == 2
    for run in children:
        assert run.info.status == "FINISHED" and run.data.metrics["env_steps"] == 2000
        assert run.data.params["num_envs_per_env_runner"] == "1" and run.data.params["torch_threads"] == "2"


@pytest.mark.slow
def test_a_smoke_compare_sweep_runs_every_algorithm_and_evaluate_restores_each(ray_session, tmp_path, capsys):
    """One trial per algorithm: each child run names its algorithm (param, tag, lac.config), logs ν
    and the episode cost every iteration, the note puts the baselines beside LAC, and lac-eval
    restores each checkpoint from MLflow (the chain only LAC's)."""
    from sweeps import evaluate

    args = cli.parse_args(["--space", "compare", "--budget", "smoke", "--seeds", "1", "--max-concurrent", "2",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                           "--storage", str(tmp_path / "ray_results"), "--experiment", "test"])
    assert _sweep(tmp_path, args) == 0
    client, parents, children = _runs(tmp_path)
    by_algo = {c.data.params["algo"]: c for c in children}
    assert sorted(by_algo) == sorted(ALGOS)  # compare.yaml: every algorithm of the package
    for algo, c in by_algo.items():
        assert c.info.status == "FINISHED" and c.data.tags["lac.algo"] == algo
        assert c.data.tags["lac.config"] == f"{algo}-compare-PointHazard-v0"
        steps = [m.step for m in client.get_metric_history(c.info.run_id, "episode_cost")]
        assert steps and steps[-1] >= 2000, (algo, steps)
        assert len(client.get_metric_history(c.info.run_id, "nu")) == len(steps)
    assert "langevin_steps" in by_algo["lac"].data.params and "langevin_steps" not in by_algo["sac_lag"].data.params
    note = parents[0].data.tags["mlflow.note.content"]
    assert "**Algorithms on `lac/PointHazard-v0`**" in note and "| ppo_lag | 1 |" in note, note
    capsys.readouterr()
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    for algo, c in by_algo.items():
        code = evaluate.main(["--run-id", c.info.run_id, "--tracking-uri", uri, "--episodes", "1", "--json",
                              "--no-progress"])
        out = capsys.readouterr().out
        assert code == 0 and json.loads(out.strip().splitlines()[-1])["algo"] == algo, out
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--run-id", by_algo["ppo_lag"].info.run_id, "--tracking-uri", uri, "--actions", "langevin"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--actions langevin is not a mode of ppo_lag" in err
    assert "accepted: --actions generator | stochastic" in err
    assert len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_a_sweep_on_a_users_own_env_lands_in_mlflow_and_restores(ray_session, tmp_path, capsys):
    """A factory in tests/ (not importable by Ray's workers from their own path): 2 trials train on
    it, their runs name the factory, and lac-eval rebuilds the env from the checkpoint's definition."""
    from lac_rllib.tasks import registry
    from sweeps import evaluate

    path = tmp_path / "mine.yaml"
    path.write_text("task: {factory: 'user_envs:make_safe', cost_limit: 5, cost_key: violation, preset: tiny,"
                    " name: mine/Line-v0}\nbudget: smoke\nseeds: {count: 2, start: 40}\n")
    args = cli.parse_args(["--config", str(path), "--max-concurrent", "2", "--experiment", "test",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")])
    assert _sweep(tmp_path, args) == 0
    client, parents, children = _runs(tmp_path)
    assert parents[0].data.tags["lac.seeds"] == "40,41" and parents[0].data.tags["lac.tasks"] == "mine/Line-v0"
    assert sorted(int(c.data.params["seed"]) for c in children) == [40, 41]
    for c in children:
        assert c.info.status == "FINISHED" and c.data.params["task"] == "mine/Line-v0"
        assert c.data.params["task_source"] == "user_envs:make_safe"
        assert c.data.metrics["cost_limit"] == 5.0 and "episode_cost" in c.data.metrics
    yaml_text = client.download_artifacts(parents[0].info.run_id, "sweep.yaml", str(tmp_path))
    assert "user_envs:make_safe" in Path(yaml_text).read_text()
    registry._TASKS.pop("mine/Line-v0")  # as in a fresh process: only the checkpoint knows the env
    capsys.readouterr()
    code = evaluate.main(["--run-id", children[0].info.run_id, "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                          "--episodes", "2", "--json", "--no-progress"])
    out = capsys.readouterr().out
    result = json.loads(out.strip().splitlines()[-1])
    assert code == 0 and result["task"] == "mine/Line-v0" and result["episodes"] == 2, out


@pytest.mark.slow
def test_a_safety_gymnasium_task_new_to_the_registry_runs_a_smoke_trial(ray_session, tmp_path):
    """SafetyCarCircle1-v0 (500-step episodes, walls as the cost) was not a task before sweep files."""
    path = tmp_path / "circle.yaml"
    path.write_text("task: SafetyCarCircle1-v0\nbudget: smoke\nseeds: 1\nset: {env_steps_per_iteration: 1000}\n")
    args = cli.parse_args(["--config", str(path), "--experiment", "test",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")])
    assert _sweep(tmp_path, args) == 0
    client, _, (child,) = _runs(tmp_path)
    assert child.info.status == "FINISHED" and child.data.params["task"] == "SafetyCarCircle1-v0"
    assert child.data.metrics["cost_limit"] == 25.0 and child.data.metrics["env_steps"] >= 2000
    assert [m.value for m in client.get_metric_history(child.info.run_id, "episode_cost")], "an episode completed"


def test_a_users_algorithm_s_folder_is_on_the_path_of_every_worker_the_sweep_starts(monkeypatch):
    """Env runners of a trial of several CPUs unpickle its config classes: the job's PYTHONPATH has
    the folder (the user's own PYTHONPATH kept after it); a sweep of the package's algorithms adds none."""
    from types import SimpleNamespace

    from sweeps.sweep import worker_env

    monkeypatch.setenv("PYTHONPATH", "/site/extra")
    assert worker_env(SimpleNamespace(user_algos={})) is None
    env = worker_env(SimpleNamespace(user_algos={"mine.a": "/mine", "mine.b": "/mine", "other": "/other"}))
    assert env == {"env_vars": {"PYTHONPATH": os.pathsep.join(["/mine", "/other", "/site/extra"])}}


@pytest.mark.parametrize("searcher", [s for s in SEARCHERS if s != "grid"])
def test_every_searcher_survives_tunes_pickling(tmp_path, searcher):
    """Tune pickles its search algorithm into the experiment state when the Tuner is built: a
    searcher that cannot be pickled fails the sweep before its first trial (Optuna 5.1's NSGA-II
    holds a lock: docs/dependencies.md)."""
    import optuna
    from ray import cloudpickle

    (tmp_path / "s.yaml").write_text(f"task: lac/PointHazard-v0\nbudget: smoke\nseeds: 2\nnum_samples: 4\n"
                                     f"searcher: {searcher}\nsearch: {{beta: {{uniform: [0.0, 20.0]}}}}\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(tmp_path / "s.yaml"),
                                          "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                                          "--storage", str(tmp_path / "rr"), "--experiment", "test"]))
    search = cloudpickle.loads(cloudpickle.dumps(search_algorithm(plan)))
    sampler = search.searcher._sampler
    expected = {"random": "RandomSampler", "nsga2": "PicklableNSGAIISampler"}.get(searcher, "TPESampler")
    assert search.repeat == 2 and type(sampler).__name__ == expected
    # the loaded sampler still samples (NSGA-II takes its new lock on every call)
    study = optuna.create_study(sampler=sampler, directions=["maximize", "minimize"]
                                if searcher in MULTI_OBJECTIVE else ["maximize"])
    study.optimize(lambda t: [t.suggest_float("x", 0, 1)] * len(study.directions), n_trials=3)
    assert len(study.trials) == 3


@pytest.mark.slow
def test_a_users_own_algorithm_runs_through_the_sweep_mlflow_the_report_and_lac_eval(ray_session, tmp_path, capsys):
    """A throwaway algorithm under tests/ (tests/algorithms/toy_algo.py: PPO-Lag's pieces, a field and
    smoke sizes of its own), named by its module path in a sweep file: its trial runs at its own
    sizes, reports its own key every iteration, lands in MLflow and the report by its path, and
    lac-eval imports it again from the checkpoint's name. No code of the package knows it."""
    from lac_rllib.algorithms import registry
    from sweeps import evaluate

    toy = "tests.algorithms.toy_algo"
    code = [*REPO.glob("lac_rllib/**/*.py"), *REPO.glob("sweeps/**/*.py"), *REPO.glob("sweeps/builtin/*.yaml"),
            *REPO.glob("benchmarks/*.py")]
    assert not [p for p in code if "toy_algo" in p.read_text()]
    path = tmp_path / "mine.yaml"
    path.write_text(f"algo: {{module: {toy}}}\nbudget: smoke\nseeds: 1\nset: {{toy_marker: 2.5}}\n")
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    args = cli.parse_args(["--config", str(path), "--experiment", "test", "--tracking-uri", uri,
                           "--storage", str(tmp_path / "rr")])
    assert _sweep(tmp_path, args) == 0
    client, (parent,), (child,) = _runs(tmp_path)
    p = child.data.params
    assert child.info.status == "FINISHED" and p["algo"] == toy and child.data.tags["lac.algo"] == toy
    # Its own field and its own smoke sizes (PPO-Lag's smoke runs (32, 32) on 500-step iterations).
    assert (p["toy_marker"], p["hidden"], p["train_batch_size_per_learner"]) == ("2.5", "[16, 16]", "400")
    markers = client.get_metric_history(child.info.run_id, "toy_marker")  # its own reported key, every row
    steps = [m.step for m in client.get_metric_history(child.info.run_id, "episode_cost")]
    assert [m.value for m in markers] == [2.5] * 5 and [m.step for m in markers] == steps == [400 * i for i in
                                                                                                range(1, 6)]
    note = parent.data.tags["mlflow.note.content"]
    assert "1 of 1 trials finished" in note and f"| mine | {toy}-mine-PointHazard-v0 (default) | 1 |" in note, note
    # lac-eval, as in a fresh process: the module is imported again by the path the checkpoint names.
    registry._USER.pop(toy)
    sys.modules.pop(toy)
    capsys.readouterr()
    rc = evaluate.main(["--run-id", child.info.run_id, "--tracking-uri", uri, "--episodes", "3", "--json",
                        "--no-progress"])
    out = capsys.readouterr().out
    result = json.loads(out.strip().splitlines()[-1])
    assert rc == 0 and (result["algo"], result["episodes"], len(result["returns"])) == (toy, 3, 3), out
    assert toy in sys.modules and "eval/generator/return_mean" in client.get_run(child.info.run_id).data.metrics


@pytest.mark.slow
def test_a_smoke_table_sweep_writes_the_table_and_the_parents_metrics(ray_session, tmp_path):
    """2 tasks x 2 algorithms x 1 seed: the parent run gets summary/table.md (rows the tasks,
    columns the algorithms, the budget said) leading its note, and its metrics (issue 35)."""
    sweep = tmp_path / "table.yaml"
    sweep.write_text("task: [lac/PointHazard-v0, lac/CostProbe-v0]\nbudget: smoke\nseeds: 1\n"
                     "groups:\n  compare: {grid: {algo: [ppo_lag, focops]}}\n")
    args = cli.parse_args(["--config", str(sweep), "--max-concurrent", "2",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                           "--storage", str(tmp_path / "ray_results"), "--experiment", "test"])
    assert _sweep(tmp_path, args) == 0
    client, parents, children = _runs(tmp_path)
    assert len(parents) == 1 and len(children) == 4
    parent = client.get_run(parents[0].info.run_id)
    table = Path(client.download_artifacts(parent.info.run_id, "summary/table.md", str(tmp_path))).read_text()
    assert "`lac/PointHazard-v0`" in table and "`lac/CostProbe-v0`" in table and "Budget: 2,000 env steps" in table
    header = next(line for line in table.splitlines() if line.startswith("| task (limit)"))
    assert "PPO-L" in header and "FOCOPS" in header  # the paper's names of ppo_lag and focops as columns
    assert "Final return and cost per task and algorithm" in parent.data.tags["mlflow.note.content"]
    m = parent.data.metrics
    assert m["trials_finished"] + m["trials_failed"] == 4 and m["configurations"] == 4, m
