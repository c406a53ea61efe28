"""A ladder of cost limits and the fixed-multiplier frontier as sweep axes (sweeps/sweep_file.py
``cost_limits`` and ``frontier``, ``--cost-limits``), from the plan to MLflow and the report."""

from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from sweeps import run as cli
from sweeps.sweep import run_sweep

LADDER = """task: lac/PointHazard-v0
algo: [ppo_lag, sac_lag]
budget: smoke
seeds: 2
cost_limits: [0, 2]
frontier: {algo: ppo_lag, nu: [0, 1, 4]}
"""


def _args(tmp_path, *extra, text=LADDER):
    path = tmp_path / "ladder.yaml"
    path.write_text(text)
    return cli.parse_args(["--config", str(path), "--experiment", "test", "--max-concurrent", "2",
                           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage",
                           str(tmp_path / "rr"), *extra])


def test_a_ladder_is_one_trial_per_configuration_limit_and_seed(tmp_path):
    plan, = cli.make_plan(_args(tmp_path))
    ladder = [t for t in plan.trials if t.group != "frontier"]
    frontier = [t for t in plan.trials if t.group == "frontier"]
    assert len(ladder) == 2 * 2 * 2 and len(frontier) == 3 * 2  # algos × limits × seeds; ν values × seeds
    assert {(t.algo, t.params["cost_limit"], t.seed) for t in ladder} == {
        (a, b, s) for a in ("ppo_lag", "sac_lag") for b in (0.0, 2.0) for s in (0, 1)}
    assert len({t.config_label() for t in ladder}) == 4  # the limit is part of the configuration
    assert {t.params["nu_fixed"] for t in frontier} == {0.0, 1.0, 4.0} and {t.algo for t in frontier} == {"ppo_lag"}
    again, = cli.make_plan(_args(tmp_path, "--cost-limits", "1,3,5"))  # the flag replaces the file's ladder
    assert sorted({t.params["cost_limit"] for t in again.trials if t.group != "frontier"}) == [1.0, 3.0, 5.0]


@pytest.mark.parametrize("argv,needle", [
    (["--cost-limits", "1,1"], "--cost-limits: [1.0, 1.0] repeats a value"),
    (["--cost-limits=-1"], "--cost-limits: Input should be greater than or equal to 0 (got -1.0)"),
])
def test_a_bad_ladder_on_the_command_line_is_one_line(tmp_path, argv, needle):
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, *argv))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


@pytest.mark.slow
def test_a_ladder_sweep_with_its_frontier_lands_in_mlflow_with_its_report(ray_session, tmp_path):
    plan, = cli.make_plan(_args(tmp_path, "--seeds", "1", text=LADDER.replace("[ppo_lag, sac_lag]", "ppo_lag")))
    assert len(plan.trials) == 2 + 3  # two limits, three fixed ν
    assert run_sweep(plan, Path(plan.storage) / plan.name, "test-commit") == 0
    client = MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    runs = client.search_runs([client.get_experiment_by_name("test").experiment_id], max_results=100)
    parent = next(r for r in runs if r.data.tags.get("lac.sweep") == "1")
    children = [r for r in runs if "mlflow.parentRunId" in r.data.tags]
    limits = sorted(c.data.metrics["cost_limit"] for c in children if c.data.params.get("group") != "frontier")
    assert limits == [0.0, 2.0] and all(c.info.status == "FINISHED" for c in children)
    assert all("multiplier/nu_at_zero" in c.data.metrics for c in children)  # how its multiplier behaved
    note = parent.data.tags["mlflow.note.content"]
    assert "Across the ladder of cost limits" in note and "R*(b)" in note, note[:3000]
    assert any(k.startswith("ladder_wins/") for k in parent.data.metrics), parent.data.metrics
    files = {f.path for f in client.list_artifacts(parent.info.run_id, "summary")}
    assert {"summary/ladder.md", "summary/ladder.csv", "summary/ladder.png", "summary/frontier_points.csv"} <= files
    summary = Path(client.download_artifacts(parent.info.run_id, "summary/summary.csv", str(tmp_path))).read_text()
    assert summary.count("-b0,") >= 1 and summary.count("-b2,") >= 1  # a row per configuration and limit


BAD_LADDERS = [
    ("cost_limits: []\n", r"my.yaml:1: cost_limits: Tuple should have at least 1 item"),
    ("cost_limits: [1, -2]\n", r"my.yaml:1: cost_limits\[1\]: Input should be greater than or equal to 0"),
    ("cost_limits: [1, 1]\n", r"my.yaml:1: cost_limits: \[1.0, 1.0\] repeats a value"),
    ("cost_limits: [1, two]\n", r"my.yaml:1: cost_limits\[1\]: Input should be a valid number"),
    ("frontier: {algo: cpo, nu: [0, 1]}\n", r"my.yaml:1: frontier.algo: cpo has no Lagrange multiplier to fix; "
                                            r"accepted: lac \| ppo_lag"),
    ("frontier: {algo: ppo_lag, nu: []}\n", r"my.yaml:1: frontier.nu: Tuple should have at least 1 item"),
    ("cost_limits: [1]\nset: {cost_limit: 2}\n", r"my.yaml:2: set.cost_limit: cost_limit set beside cost_limits"),
    ("cost_limits: [1]\nsearch: {beta: {uniform: [0, 1]}}\n", r"my.yaml:1: cost_limits: cost_limits with a search"),
]


@pytest.mark.parametrize("text,needle", BAD_LADDERS)
def test_a_bad_ladder_or_frontier_is_one_line_naming_the_key_before_ray(tmp_path, monkeypatch, capsys, text, needle):
    from tests.sweeps.test_sweep_file import test_a_bad_file_is_one_line_naming_the_key_before_ray as check

    check(tmp_path, monkeypatch, capsys, text, needle)


@pytest.mark.slow
def test_a_ladder_sweep_confirms_its_least_mean_regret_configuration_at_every_limit(ray_session, tmp_path, capsys):
    """--confirm-top 1 --confirm-by mean-regret: the winner is the configuration of least mean
    regret in the search's ladder report; the confirmation reruns it at both limits beside the
    frontier on a fresh seed, and its note judges it at each limit with the regret on both seeds."""
    import pandas as pd

    from sweeps.reports import ladder

    # Limits a smoke run's cost sits under (a random policy's episodes cost ~3-7 here): every configuration
    # and fixed ν is feasible at both, so a regret winner exists; 3 seeds, so R*(b) has held-out seeds.
    text = (LADDER.replace("[ppo_lag, sac_lag]", "[ppo_lag, p3o]").replace("nu: [0, 1, 4]", "nu: [0, 4]")
            .replace("cost_limits: [0, 2]", "cost_limits: [30, 60]"))
    path = tmp_path / "ladder.yaml"
    path.write_text(text)
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    rc = cli.main(["--config", str(path), "--seeds", "3", "--confirm-top", "1", "--confirm-by", "mean-regret",
                   "--confirm-seeds", "1", "--experiment", "test", "--max-concurrent", "2", "--tracking-uri", uri,
                   "--storage", str(tmp_path / "rr")])
    assert rc == 0, capsys.readouterr().err[-2000:]
    client = MlflowClient(uri)
    runs = client.search_runs([client.get_experiment_by_name("test").experiment_id], max_results=100)
    parents = {r.data.tags["lac.sweep_name"]: r for r in runs if r.data.tags.get("lac.sweep") == "1"}
    search = next(p for n, p in parents.items() if not n.endswith("-confirm"))
    confirmation = next(p for n, p in parents.items() if n.endswith("-confirm"))
    table = pd.read_csv(client.download_artifacts(search.info.run_id, "summary/ladder.csv", str(tmp_path)))
    table[["param", "value"]] = table[["param", "value"]].astype(object).fillna("")  # the CSV's empty cells
    best = ladder.wins(table).sort_values("mean_regret").iloc[0]["configuration"]  # e.g. "ppo_lag ladder"
    confirmed = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == confirmation.info.run_id]
    top1 = [c for c in confirmed if c.data.params["group"] == "top1"]
    assert {c.data.params["algo"] for c in top1} == {best.split(" ")[0]}  # here a configuration is its algorithm
    assert sorted(c.data.metrics["cost_limit"] for c in top1) == [30.0, 60.0]
    from sweeps.seeds import fresh_seeds

    assert {int(c.data.params["seed"]) for c in confirmed} == set(fresh_seeds([0, 1, 2], 1))  # none the search's
    assert sum(c.data.params["group"] == "frontier" for c in confirmed) == 2
    note = confirmation.data.tags["mlflow.note.content"]
    assert "across the ladder (the search's best by their mean regret over the ladder)" in note, note[:3000]
    assert "top1 held up at" in note and "of 2 limits; worst regret" in note, note[:3000]
