"""What follows a finished sweep (sweeps/followup.py): one read-back of its trials, one builder of
the confirmation both flows run (--confirm-top and a tuned comparison), on fresh seeds."""

import json
from pathlib import Path
from types import SimpleNamespace

import pytest
from mlflow.tracking import MlflowClient

from sweeps import followup, sweep_file
from sweeps.record import SWEEP_FILE
from sweeps.seeds import fresh_seeds
from sweeps.tracking import SweepTracker
from sweeps.tuned import TunedPlan, confirmation_sweep

TASK = "lac/PointHazard-v0"


def test_both_confirmations_come_from_one_builder_on_fresh_seeds(monkeypatch):
    built = []
    original = followup.build_confirmation
    monkeypatch.setattr(followup, "build_confirmation", lambda *a, **k: built.append(a[1]) or original(*a, **k))
    text = f"task: {TASK}\nbudget: smoke\nseeds: 3\nnum_samples: 4\nsearch: {{beta: {{uniform: [0, 20]}}}}\n"
    top = [{"group": "top1", "config": "c", "fields": {"beta": 1.0}, "search": {}}]
    plain = followup.confirmation_file(sweep_file.load("x.yaml", text), top, 2, "quick", "x-confirm")
    # How the sweep chose its configurations is replaced by the winners, run by grid on fresh seeds.
    assert plain.search is None and plain.searcher == "grid" and plain.budget == "quick"
    assert plain.seed_list() == fresh_seeds((0, 1, 2), 2) and list(plain.groups) == ["top1", "default"]
    tuned = sweep_file.load("t.yaml", f"name: t\ntask: {TASK}\nbudget: smoke\nalgo: [lac, ppo_lag]\n"
                                      "tune: {seeds: 3}\n")
    search = SimpleNamespace(seeds=(0, 1, 2), sweep=SimpleNamespace(set={}), tasks=(TASK,))
    tp = TunedPlan(sweep=tuned, searches={"lac": search, "ppo_lag": search}, registry=Path("registry"))
    joint = confirmation_sweep(tp, {"lac": top, "ppo_lag": top})
    assert joint.seed_list() == fresh_seeds((0, 1, 2), 5) and joint.name == "t-confirm" and joint.tune is None
    assert built[0] == {"top1": {"set": {"beta": 1.0}}, "default": {}}  # one builder made both
    assert list(built[1]) == ["lac-tuned1", "lac-default", "ppo_lag-tuned1", "ppo_lag-default"] and len(built) == 2


def record_sweep(tmp_path, name: str, runs: list[dict], labels: str = "config") -> SimpleNamespace:
    """A finished sweep as its directory and MLflow hold it: ``sweep.json`` naming its parent run, and
    one child run per trial (``runs``: group, seed, algo, config label, return, cost), each as the
    trainable logs it (params, tags, its learning curve over 3 iterations)."""
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    tracker = SweepTracker(uri, "test")
    parent = tracker.start(name, params={}, tags={"lac.sweep_name": name})
    client = MlflowClient(uri)
    for i, r in enumerate(runs):
        child = client.create_run(tracker.experiment_id, run_name=r[labels], tags={
            "mlflow.parentRunId": parent, "lac.trial_id": f"t{i:03d}", "lac.config": r[labels],
            "lac.default_config": "0", "lac.algo": r["algo"]}).info.run_id
        for k, v in {"task": TASK, "seed": r["seed"], "group": r["group"], "swept_param": "", "swept_value": "null",
                     "timesteps": 3000, "algo": r["algo"]}.items():
            client.log_param(child, k, v)
        for step in (1000, 2000, 3000):
            client.log_metric(child, "episode_return", r["return"], step=step)
            client.log_metric(child, "episode_cost", r["cost"], step=step)
        client.log_metric(child, "cost_limit", 2.0, step=3000)
        client.set_terminated(child, "FINISHED")
    sweep_dir = tmp_path / "rr" / name
    sweep_dir.mkdir(parents=True)
    (sweep_dir / SWEEP_FILE).write_text(json.dumps({"parent_run_id": parent, "plan": {}, "infra": {}}))
    return SimpleNamespace(tracking_uri=uri, experiment="test", storage=str(tmp_path / "rr"), name=name)


def test_a_finished_sweep_reads_back_once_with_its_summary_and_each_configurations_fields(tmp_path):
    runs = [{"group": g, "seed": s, "algo": "ppo_lag", "config": f"ppo_lag-{g}-PointHazard-v0", "return": ret,
             "cost": 1.0} for g, ret in (("a", 5.0), ("b", 3.0)) for s in (0, 1, 2)]
    plan = record_sweep(tmp_path, "s", runs)
    trials, summary = followup.read_back(plan, ("algo",))
    assert len(trials) == 6 and sorted(summary["n_seeds"]) == [3, 3]
    assert followup.fields_of(trials, ("algo", "beta")) == {f"ppo_lag-{g}-PointHazard-v0": {"algo": "ppo_lag"}
                                                           for g in "ab"}


@pytest.mark.parametrize("how", [
    "search: default\nsearcher: random\nnum_samples: 4\nseeds: 1\nenv_steps_budget: 8000\n",
    "search: pbt\npbt: {members: 2, interval: 1000}\n"])
def test_a_budgeted_search_and_a_population_are_confirmed_as_grids(how):
    """What chose the configurations (an env-step budget, a population) stays with the search: the
    confirmation is a grid of the winners beside the default, on fresh seeds."""
    from sweeps.followup import confirmation_file
    from sweeps.sweep_file import SweepFile, load

    sweep = load("s.yaml", "task: lac/PointHazard-v0\nalgo: ppo_lag\nbudget: smoke\n" + how)
    top = [{"group": "top1", "fields": {"lr": 0.001}}]
    cfile = confirmation_file(sweep, top, 2, "smoke", "s-confirm")
    assert isinstance(cfile, SweepFile) and cfile.searcher == "grid" and cfile.env_steps_budget is None
    assert cfile.pbt is None and set(cfile.groups) == {"top1", "default"}
