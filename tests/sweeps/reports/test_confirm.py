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
from sweeps.followup import confirmation_file
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
                          "cost_mean": cost, "cost_limit": lim, "feasible": cost <= lim, "is_default": d,
                          "n_seeds": 3, "group": c} for c, r, lo, cost, lim, d in rows])


def test_winners_are_ranked_by_the_lower_end_of_their_return_interval():
    assert list(confirm.rank(_summary(), 3)["config"]) == ["steady", "lucky", "single"]
    top = confirm.winners(_summary(), {"steady": {"beta": 1.0}, "lucky": {"beta": 5.0}}, 2)
    assert [(w["group"], w["fields"]) for w in top] == [("top1", {"beta": 1.0}), ("top2", {"beta": 5.0})]


def test_held_up_compares_the_confirmed_mean_with_the_search_interval():
    search = {"return_mean": 4.0, "return_mean_ci_low": 3.5}
    assert confirm.held_up(search, {"return_mean": 3.6, "feasible": True})
    assert not confirm.held_up(search, {"return_mean": 3.4, "feasible": True})
    assert not confirm.held_up(search, {"return_mean": 9.0, "feasible": False})


@pytest.mark.slow
def test_a_smoke_search_then_its_confirmation_on_fresh_seeds(ray_session, tmp_path, monkeypatch, capsys):
    """End to end: 3 sampled configurations x 2 seeds (0, 1), then the best by the lower bound
    beside the default on fresh seeds 2000, 3000 (sweeps/seeds.py); the confirmation's note gives the verdict."""
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
    assert sorted({int(c.data.params["seed"]) for c in confirmed}) == [2000, 3000]  # no stream of the search's
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
    c = confirmation_file(sweep, top, 3, "quick", "x-confirm", baselines=("ppo_lag",))
    # fresh in every stream: 1,000 apart, from the first multiple at least 1,000 past the largest (sweeps/seeds.py)
    assert c.seed_list() == (2000, 3000, 4000) and c.budget == "quick" and c.name == "x-confirm"
    assert {g: dict(grp.set) for g, grp in c.groups.items()} == {
        "top1": {"langevin_steps": 9}, "default": {}, "baseline-ppo_lag": {"algo": "ppo_lag"}}
    assert confirm.varied_fields(sweep) == ["algo", "langevin_steps"]


# Over a ladder of cost limits (sweeps/reports/ladder.py): the hand-made trials of test_ladder.py,
# where ppo_lag's regrets are 0, 1, -1 (worst 1, mean 0) and sac_lag's 1, 0, 1 (worst 1, mean 2/3).
def _ladder_trials():
    from tests.sweeps.reports.test_ladder import trials

    return trials()


def _fields_of(trials):
    return {c: {"algo": a} for c, a in zip(trials["config"], trials["algo"])}


def test_winners_by_mean_regret_carry_their_figures_at_every_limit(capsys):
    trials = _ladder_trials()
    top = confirm.regret_winners(trials, _fields_of(trials), 1, "mean-regret")
    # ppo_lag is infeasible at b = 5 (one seed of three over): it has no regret over the ladder and is
    # never chosen, though its regrets where feasible (0, -3) are the smaller.
    assert [(w["name"], w["fields"]) for w in top] == [("sac_lag", {"algo": "sac_lag"})]
    assert top[0]["search"] == {"worst_regret": pytest.approx(1.0), "mean_regret": pytest.approx(1 / 3)}
    assert sorted(top[0]["by_limit"]) == [5.0, 15.0, 25.0]
    assert [top[0]["by_limit"][b]["regret"] for b in (5.0, 15.0, 25.0)] == pytest.approx([1.0, 1.0, -1.0])
    assert top[0]["by_limit"][15.0]["return_mean"] == pytest.approx(5.0)
    both = confirm.regret_winners(trials, _fields_of(trials), 2, "worst-regret")  # two asked, one qualifies
    assert [w["name"] for w in both] == ["sac_lag"] and [w["group"] for w in both] == ["top1"]
    only_ppo = trials[trials["algo"].ne("sac_lag")]
    assert confirm.regret_winners(only_ppo, _fields_of(only_ppo), 1, "worst-regret") == []
    assert "no configuration has a worst regret to choose by (ppo_lag: infeasible at b = 5)" in capsys.readouterr().out


def test_by_return_a_configuration_that_leads_at_several_limits_is_one_winner_and_the_frontier_none():
    rows = [("a-b1", 5.0, 4.0, "g"), ("a-b2", 6.0, 4.5, "g"), ("c-b1", 3.0, 2.0, "g"), ("nu-b1", 9.0, 8.0, "frontier")]
    summary = pd.DataFrame([{"config": c, "return_mean": r, "return_mean_ci_low": lo, "return_mean_ci_high": r + 1,
                             "cost_mean": 0.0, "cost_limit": 1.0, "feasible": True, "is_default": False,
                             "n_seeds": 3, "group": g} for c, r, lo, g in rows])
    fields = {"a-b1": {"beta": 1.0}, "a-b2": {"beta": 1.0}, "c-b1": {"beta": 2.0}, "nu-b1": {}}
    top = confirm.winners(summary, fields, 2)
    assert [(w["config"], w["fields"]) for w in top] == [("a-b2", {"beta": 1.0}), ("c-b1", {"beta": 2.0})]


def test_a_confirmation_of_several_algorithms_runs_each_winners_own_and_no_default():
    sweep = sweep_file.load("x.yaml", "task: lac/PointHazard-v0\nalgo: [ppo_lag, sac_lag]\nbudget: smoke\n"
                                      "seeds: 2\ncost_limits: [0, 2]\nfrontier: {algo: ppo_lag, nu: [0, 1]}\n")
    top = [{"group": "top1", "config": "sac_lag-b0", "fields": {"algo": "sac_lag"}, "search": {}}]
    c = confirmation_file(sweep, top, 3, "smoke", "x-confirm")
    assert {g: dict(grp.set) for g, grp in c.groups.items()} == {"top1": {"algo": "sac_lag"}}
    assert c.algo == ("lac",) and c.cost_limits == (0.0, 2.0) and c.frontier.nu == (0.0, 1.0)  # rerun beside it


def test_the_verdict_across_a_ladder_is_per_limit_with_the_regret_on_fresh_seeds():
    trials = _ladder_trials()
    top = confirm.regret_winners(trials, _fields_of(trials), 1, "mean-regret")
    # The confirmation's summary: top1 held up at b = 5 (2.0 ≥ its low end) and b = 25, not at 15 (cost 16 > 15).
    confirmed = pd.DataFrame([{"group": "top1", "cost_limit": b, "return_mean": r, "return_mean_ci_low": r,
                               "return_mean_ci_high": r, "cost_mean": c, "feasible": c <= b, "n_seeds": 2,
                               "feasible_fraction": float(c <= b)} for b, r, c in ((5.0, 2.0, 4.0), (15.0, 9.0, 16.0),
                                                                                  (25.0, 9.0, 20.0))])
    fresh = trials.assign(group=trials["group"].where(trials["group"].eq("frontier"), "top1"))
    fresh = fresh[fresh["group"].eq("frontier") | fresh["algo"].eq("sac_lag")]
    text = confirm.confirmation_markdown(top, confirmed, fresh)
    assert "| top1 | sac_lag | 15 |" in text and "held up at 2 of 3 limits" in text, text
    # The fresh seeds are the search's own here, so their regrets are the search's: worst 1, mean 1/3.
    assert "worst regret 1.00 on the search's seeds, 1.00 on the fresh ones; mean regret 0.33, 0.33" in text, text


@pytest.mark.parametrize("extra,needle", [
    (["--confirm-top", "1", "--confirm-by", "worst-regret"],
     "--confirm-by worst-regret: the regret over a ladder needs the sweep's frontier"),
    (["--confirm-by", "mean-regret"], "--confirm-by mean-regret without --confirm-top"),
    (["--confirm-top", "1", "--confirm-by", "best"],
     "--confirm-by best; accepted: return | worst-regret | mean-regret"),
])
def test_a_regret_choice_without_a_ladder_and_frontier_is_one_line_before_ray(tmp_path, extra, needle):
    path = tmp_path / "l.yaml"
    path.write_text("task: lac/PointHazard-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\ncost_limits: [0, 2]\n")
    args = cli.parse_args(["--config", str(path), "--tracking-uri", f"sqlite:///{tmp_path / 'm.db'}",
                           "--storage", str(tmp_path / "rr"), *extra])
    with pytest.raises(ValueError) as e:
        cli.make_plan(args)
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_regret_choice_on_one_seed_is_refused_before_ray(tmp_path):
    """R*(b) chooses ν on some of the frontier's seeds and measures it on others: one seed cannot."""
    path = tmp_path / "l.yaml"
    path.write_text("task: lac/PointHazard-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\ncost_limits: [0, 2]\n"
                    "frontier: {algo: ppo_lag, nu: [0, 1]}\n")
    args = cli.parse_args(["--config", str(path), "--tracking-uri", f"sqlite:///{tmp_path / 'm.db'}",
                           "--storage", str(tmp_path / "rr"), "--confirm-top", "1", "--confirm-by", "worst-regret"])
    with pytest.raises(ValueError, match=r"--confirm-by worst-regret with 1 seed\(s\).*accepted: --seeds 3 or more"):
        cli.make_plan(args)
