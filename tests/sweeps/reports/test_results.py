"""A sweep's close (sweeps/reports/results.py): what the parent run's report holds, end to end."""

import pytest
import yaml
from mlflow.tracking import MlflowClient

from sweeps import run as cli
from sweeps import sweep_file


def _runs(uri):
    client = MlflowClient(uri)
    runs = client.search_runs([client.get_experiment_by_name("test").experiment_id], max_results=100)
    parent = next(r for r in runs if r.data.tags.get("lac.sweep") == "1")
    return client, parent, [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent.info.run_id]


def _main(tmp_path, monkeypatch, text, *extra):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(text)
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    rc = cli.main(["--config", str(tmp_path / "s.yaml"), "--max-concurrent", "2", "--tracking-uri", uri,
                   "--storage", str(tmp_path / "rr"), "--experiment", "test", *extra])
    assert rc == 0
    return uri


@pytest.mark.slow
def test_a_multi_objective_search_holds_a_pareto_set(ray_session, tmp_path, monkeypatch):
    import optuna

    uri = _main(tmp_path, monkeypatch, "task: lac/PointHazard-v0\nbudget: smoke\nseeds: 1\nnum_samples: 5\n"
                "searcher: nsga2\nsearch: {beta: {uniform: [0.0, 20.0]}, langevin_steps: {int: [2, 8]}}\n")
    study = optuna.load_study(study_name="s-PointHazard-v0-smoke", storage=f"sqlite:///{tmp_path / 'optuna.db'}")
    assert [d.name for d in study.directions] == ["MAXIMIZE", "MINIMIZE"]
    assert len(study.trials) == 5 and all(t.state.name == "COMPLETE" for t in study.trials)
    pareto = study.best_trials
    assert pareto and all(len(t.values) == 2 for t in pareto)
    assert all("constraints:episode_cost_minus_limit" in t.system_attrs for t in study.trials)  # the limit reached it
    client, parent, _ = _runs(uri)
    note = parent.data.tags["mlflow.note.content"]
    assert f"**Pareto set** of the multi-objective search ({len(pareto)} configurations" in note
    assert "| within the limit |" in note and ("| yes |" in note or "| no |" in note)
    assert "**Hyperparameter importance** (fANOVA over configurations): return: " in note
    files = {f.path for f in client.list_artifacts(parent.info.run_id, "summary")}
    assert {"summary/pareto.json", "summary/frontier.html", "summary/frontier.png", "summary/importance.png"} <= files


@pytest.mark.slow
def test_the_ablation_s_unconstrained_arm_runs_with_nu_0_throughout(ray_session, tmp_path, monkeypatch):
    """The reference arm of the default ablation, taken from its file, at the smoke budget."""
    ablation = yaml.safe_load(sweep_file.builtin_path("ablation").read_text())
    arm = ablation["groups_at"][0]["groups"]["unconstrained"]
    assert arm == ablation["groups"]["unconstrained"]
    uri = _main(tmp_path, monkeypatch, yaml.safe_dump({
        "task": "lac/PointHazard-v0", "budget": "smoke", "seeds": 1,
        "groups": {"unconstrained": arm, "VT": {"grid": {"langevin_steps": [10]}}},
        "set": {"env_steps_per_iteration": 250, "nu_init": 0.5}}))  # ν would move from 0.5 if it were free
    client, parent, children = _runs(uri)
    by_group = {c.data.params["group"]: c for c in children}
    nu = [m.value for m in client.get_metric_history(by_group["unconstrained"].info.run_id, "nu")]
    assert len(nu) == 8 and nu == [0.0] * 8
    note = parent.data.tags["mlflow.note.content"]
    assert "**Safety per configuration**" in note and "| unconstrained |" in note


def test_the_evaluation_blocks_share_of_the_trials_time_is_their_seconds_against_training():
    import pandas as pd

    from sweeps.reports.results import evaluation_share

    trials = pd.DataFrame({"eval_time_s": [3.0, 5.0, float("nan")], "wall_time_s": [36.0, 36.0, 40.0]})
    line = evaluation_share(trials)
    # Two trials ran a block: 8 s of evaluation against 72 s of training, 10% of their 80 s.
    assert line == ("Evaluation blocks: 4.0 s per trial on average, 10% of the 2 trials' time "
                    "(training 36.0 s per trial).")
    assert evaluation_share(trials.assign(eval_time_s=float("nan"))) == ""
