"""Confirmation: a sweep's winners, picked by the lower end of their return interval, rerun on
seeds the sweep never saw (sweeps/reports/confirm.py, ``--confirm-top``)."""

import json
import math
from pathlib import Path

import pandas as pd
import pytest
from mlflow.tracking import MlflowClient

from sweeps import run as cli
from sweeps import sweep_file
from sweeps.reports import confirm


def _summary():
    rows = [  # config, return mean, its CI low, cost, limit, default
        ("lucky", 5.0, -3.0, 1.0, 2.0, False),   # the highest mean, one wild seed: a wide interval
        ("steady", 4.0, 3.5, 1.0, 2.0, False),   # the best lower bound
        ("unsafe", 9.0, 8.0, 3.0, 2.0, False),   # infeasible
        ("default", 6.0, 5.0, 0.0, 2.0, True),   # the reference, never a winner
        ("single", 4.5, math.nan, 0.5, 2.0, False),  # one seed: no interval, ranked last
    ]
    return pd.DataFrame([{"config": c, "return_mean": r, "return_mean_ci_low": lo, "return_mean_ci_high": r + 1,
                          "cost_mean": cost, "cost_limit": lim, "mean_feasible": cost <= lim, "is_default": d,
                          "n_seeds": 3, "group": c} for c, r, lo, cost, lim, d in rows])


def test_winners_are_ranked_by_the_lower_end_of_their_return_interval():
    assert list(confirm.rank(_summary(), 3)["config"]) == ["steady", "lucky", "single"]
    top = confirm.winners(_summary(), {"steady": {"beta": 1.0}, "lucky": {"beta": 5.0}}, 2)
    assert [(w["group"], w["fields"]) for w in top] == [("top1", {"beta": 1.0}), ("top2", {"beta": 5.0})]


def test_held_up_compares_the_confirmed_mean_with_the_search_interval():
    search = {"return_mean": 4.0, "return_mean_ci_low": 3.5}
    assert confirm.held_up(search, {"return_mean": 3.6, "mean_feasible": True})
    assert not confirm.held_up(search, {"return_mean": 3.4, "mean_feasible": True})
    assert not confirm.held_up(search, {"return_mean": 9.0, "mean_feasible": False})


@pytest.mark.slow
def test_a_smoke_search_then_its_confirmation_on_fresh_seeds(ray_session, tmp_path, monkeypatch, capsys):
    """End to end: 3 sampled configurations x 2 seeds (0, 1), then the best by the lower bound
    beside the default on seeds 2, 3; the confirmation's note gives the verdict."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(
        "task: lac/PointHazard-v0\nbudget: smoke\nseeds: 2\nnum_samples: 3\nsearcher: random\n"
        "set: {cost_limit: 1000.0}\nsearch: {beta: {uniform: [0.0, 20.0]}}\n")
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    rc = cli.main(["--config", str(tmp_path / "s.yaml"), "--confirm-top", "1", "--confirm-seeds", "2",
                   "--max-concurrent", "2", "--tracking-uri", uri, "--storage", str(tmp_path / "rr"),
                   "--experiment", "test"])
    assert rc == 0, capsys.readouterr().err[-2000:]
    client = MlflowClient(uri)
    runs = client.search_runs([client.get_experiment_by_name("test").experiment_id], max_results=100)
    parents = {r.data.tags["lac.sweep_name"]: r for r in runs if r.data.tags.get("lac.sweep") == "1"}
    assert set(parents) == {"s-PointHazard-v0-smoke", "s-PointHazard-v0-smoke-confirm"}
    search, confirmation = parents["s-PointHazard-v0-smoke"], parents["s-PointHazard-v0-smoke-confirm"]
    children = lambda p: [r for r in runs if r.data.tags.get("mlflow.parentRunId") == p.info.run_id]  # noqa: E731
    assert sorted({int(c.data.params["seed"]) for c in children(search)}) == [0, 1]
    confirmed = children(confirmation)
    assert sorted({int(c.data.params["seed"]) for c in confirmed}) == [2, 3]  # disjoint from the search's
    assert sorted(c.data.params["group"] for c in confirmed) == ["default", "default", "top1", "top1"]
    # top1 is the search's configuration with the best lower bound of its return interval.
    summary = pd.read_csv(client.download_artifacts(search.info.run_id, "summary/summary.csv", str(tmp_path)))
    best = summary[~summary["is_default"]].sort_values("return_mean_ci_low", ascending=False).iloc[0]
    beta = {json.loads(c.data.params["beta"]) for c in children(search) if c.data.tags["lac.config"] == best["config"]}
    assert {json.loads(c.data.params["beta"]) for c in confirmed if c.data.params["group"] == "top1"} == beta
    note = confirmation.data.tags["mlflow.note.content"]
    assert "**Confirmation on fresh seeds**" in note and "| top1 |" in note and ("| yes |" in note or "| no |" in note)
    assert search.data.tags["lac.confirmed_by"] == "s-PointHazard-v0-smoke-confirm"
    assert (Path(tmp_path / "rr" / "s-PointHazard-v0-smoke-confirm" / "sweep.yaml")).exists()


def test_the_confirmation_reruns_the_winners_the_default_and_the_baselines_on_fresh_seeds():
    sweep = sweep_file.load("x.yaml", "task: lac/PointHazard-v0\nseeds: {count: 2, start: 5}\nbudget: smoke\n"
                                      "groups:\n  compare: {grid: {algo: [lac, ppo_lag]}}\n"
                                      "  T: {grid: {langevin_steps: [5, 9]}}\n")
    top = [{"group": "top1", "config": "T-langevin_steps=9", "fields": {"langevin_steps": 9}, "search": {}}]
    c = confirm.confirmation_file(sweep, top, 3, "quick", "x-confirm", baselines=("ppo_lag",))
    assert c.seed_list() == (7, 8, 9) and c.budget == "quick" and c.name == "x-confirm"
    assert {g: dict(grp.set) for g, grp in c.groups.items()} == {
        "top1": {"langevin_steps": 9}, "default": {}, "baseline-ppo_lag": {"algo": "ppo_lag"}}
    assert confirm.varied_fields(sweep) == ["algo", "langevin_steps"]
