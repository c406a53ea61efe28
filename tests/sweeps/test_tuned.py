"""Algorithms compared at equal tuning budgets (sweeps/tuned.py, sweeps/reports/tuned.py): each
algorithm's declared search space, the equal budgets, the report's figures by hand, and the whole
comparison from one sweep file to the registry and back through ``preset: tuned``."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lac_rllib.algorithms.registry import ALGOS, search_space
from sweeps import run as cli
from sweeps import spaces
from sweeps.reports import tuned as report
from sweeps.tuned import check_equal_budgets

TASKS = ("lac/PointHazard-v0", "SafetyPointGoal1-v0", "focops/SwimmerVelocity-v0")  # tiny, safety_gym, mujoco

TUNED = """task: lac/PointHazard-v0
budget: smoke
algo: [lac, ppo_lag]
eval_episodes: 1
tune: {num_samples: 2, seeds: 1, confirm_seeds: 2}
"""


def _args(tmp_path, text, *extra):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    return cli.parse_args(["--config", str(path), "--experiment", "test", "--tracking-uri",
                           f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr"),
                           "--registry", str(tmp_path / "registry"), *extra])


@pytest.mark.parametrize("algo", list(ALGOS))
def test_every_algorithm_declares_a_search_space_that_holds_its_defaults(algo):
    declared = search_space(algo)
    assert len(declared) >= 3 and all(d.source for d in declared.values()), declared
    for task in TASKS:
        search = spaces.declared_search(algo, task, "quick", {}, "default")
        base = spaces.trial_params(task, "quick", {"algo": algo})
        assert list(search) == list(declared)
        for name, dist in search.items():
            (kind, args), = dist.items()
            if kind == "choice":  # the default among the values (LAC's β: the paper's grid, from 0)
                assert len(set(args)) > 1 and base[name] in args, (algo, task, name, base[name], dist)
                continue
            low, high = args
            assert low < high and low <= base[name] <= high, (algo, task, name, base[name], dist)


def test_search_default_names_the_space_and_a_file_may_narrow_it(tmp_path):
    whole, = cli.make_plan(_args(tmp_path, "algo: trpo_lag\nbudget: smoke\nsearch: default\nnum_samples: 1\n"))
    assert set(whole.sweep.search) == {"target_kl", "cg_damping", "lagrangian_lr", "critic_lr"}
    assert whole.sweep.search["target_kl"].loguniform == pytest.approx((0.02 / 3, 0.06))  # around the tiny default
    narrow, = cli.make_plan(_args(tmp_path, "budget: smoke\nnum_samples: 1\nsearch:\n  langevin_steps: default\n"
                                            "  temperature: {loguniform: [1.0e-4, 1.0e-3]}\n", "--name", "n2"))
    assert narrow.sweep.search["langevin_steps"].int == (10, 100)
    assert narrow.sweep.search["temperature"].loguniform == (1e-4, 1e-3) and len(narrow.sweep.search) == 2
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, "budget: smoke\nsearch: {alpha: default}\n", "--name", "n3"))
    assert "alpha is not in lac's search space; accepted: langevin_steps" in str(e.value) and "\n" not in str(e.value)


def test_a_tuned_comparison_gives_every_algorithm_the_same_budget(tmp_path, capsys):
    from sweeps.tuned import budget_of, print_tuned_plan

    tp, = cli.make_plan(_args(tmp_path, TUNED.replace("[lac, ppo_lag]", "[lac, ppo_lag, sac_lag, trpo_lag]")))
    budgets = {a: budget_of(p) for a, p in tp.searches.items()}
    assert set(budgets) == {"lac", "ppo_lag", "sac_lag", "trpo_lag"} and set(budgets.values()) == {(2, 1, 2000)}
    assert all(set(p.sweep.search) == set(search_space(a)) for a, p in tp.searches.items())
    print_tuned_plan(tp)
    out = capsys.readouterr().out
    assert out.count("2 samples × 1 seeds × 2,000 env steps = 4,000 env steps") == 4 and "CPU-hours" in out
    assert "  each search: 2 samples: 1 from TPE's random start, 1 steered by TPE" in out  # sweeps/search.py
    with pytest.raises(ValueError) as e:  # a hand-made unequal plan
        check_equal_budgets({"lac": (8, 3, 40_000), "ppo_lag": (8, 3, 40_000), "sac_lag": (8, 2, 40_000)})
    assert "sac_lag gets 8 samples × 2 seeds" in str(e.value) and "lac 8 samples × 3 seeds" in str(e.value)


@pytest.mark.parametrize("text,needle", [
    (TUNED + "search: default\n", "s.yaml:6: search: search with tune"),
    (TUNED + "cost_limits: [0, 2]\n", "cost_limits with tune"),
    (TUNED.replace("num_samples: 2", "num_samples: 0"), "tune.num_samples: Input should be greater than or equal to 1"),
    (TUNED.replace("num_samples: 2", "num_samples: 1"), "s.yaml:5: tune.num_samples: num_samples 1 with searcher tpe: "
     "all 1 come from TPE's random start, none is steered by TPE; accepted: num_samples >= 2 with tpe"),
    (TUNED.replace("num_samples: 2", "samples: 2"), "unknown key 'samples' (did you mean num_samples?)"),
])
def test_bad_tune_sections_are_refused_in_one_line(tmp_path, text, needle):
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, text))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_tuned_tpe_search_too_small_to_steer_a_draw_is_refused_random_is_not(tmp_path):
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, TUNED, "--tune", "1"))
    assert "--tune: num_samples 1 with searcher tpe" in str(e.value) and "\n" not in str(e.value), str(e.value)
    tp, = cli.make_plan(_args(tmp_path, TUNED.replace("num_samples: 2", "num_samples: 1, searcher: random")))
    assert tp.sweep.tune.num_samples == 1


def test_the_table_spaces_take_tune_from_the_command_line_one_comparison_per_task(tmp_path):
    plans = cli.make_plan(cli.parse_args(["--space", "table1", "--budget", "smoke", "--tune", "2", "--tune-seeds",
                                          "1", "--confirm-seeds", "2", "--tracking-uri",
                                          f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")]))
    assert len(plans) == 4 and len({tp.task for tp in plans}) == 4  # the table's four tasks, each tuned apart
    tp = plans[0]
    assert set(tp.searches) == {"cpo", "cup", "focops", "ppo_lag", "trpo_lag", "lac"}
    assert tp.sweep.tune.num_samples == 2 and tp.sweep.tune.confirm_seeds == 2
    assert tp.searches["cpo"].sweep.set == {"preset": "ssa"}  # each column's preset goes with its algorithm
    assert {tuple(p.seeds) for p in tp.searches.values()} == {(0,)}


def test_confirm_top_beside_tune_is_refused(tmp_path):
    with pytest.raises(ValueError, match="--confirm-top with tune"):
        cli.make_plan(_args(tmp_path, TUNED, "--confirm-top", "1"))


def test_the_gap_is_paired_by_seed_and_p_improvement_and_the_winners_curse_by_hand():
    # Each fresh seed's luck moves tuned and default alike: paired, the differences 1.0, 1.1, 0.9 say tuning
    # helps; apart (Welch) the seeds' spread (0, 5, 10) hides it.
    tuned = {"by_seed": {3: 1.0, 4: 6.1, 5: 10.9}}
    default = {"by_seed": {3: 0.0, 4: 5.0, 5: 10.0, 6: 7.0}}  # seed 6: the tuned run failed there
    gap, low, high, pairs = report.paired_gap(tuned, default)
    assert pairs == 3 and gap == pytest.approx(1.0) and 0 < low < gap < high
    from sweeps.reports import verdicts

    welch = verdicts.difference_interval(list(tuned["by_seed"].values()), list(default["by_seed"].values())[:3])
    assert welch[1] < 0  # the unpaired interval crosses 0
    assert report.winners_curse(search_return=5.0, fresh_return=3.0) == 2.0
    assert np.isnan(report.paired_gap({"by_seed": {3: 1.0}}, {"by_seed": {3: 2.0}})[1])  # one pair: no interval


def test_search_spread_by_hand():
    summary = pd.DataFrame({"n_seeds": [3, 3, 3, 3, 0], "return_mean": [1.0, 2.0, 3.0, 10.0, 99.0],
                            "cost_mean": [5.0, 1.0, 3.0, 2.0, 0.0], "feasible": [False, True, True, True, True]})
    s = report.search_spread(summary)  # the unfinished configuration (n_seeds 0) is left out
    assert s["configurations"] == 4
    assert s["return_best_minus_median"] == pytest.approx(10 - 2.5) and s["return_iqr"] == pytest.approx(4.75 - 1.75)
    assert s["cost_best_minus_median"] == pytest.approx(1 - 2.5) and s["cost_iqr"] == pytest.approx(3.5 - 1.75)
    assert s["feasible_share"] == 0.75


def _confirmation(rows):
    """(group, return, cost[, seed[, task[, status]]]) rows of a confirmation at limit 2."""
    out = []
    for i, row in enumerate(rows):
        g, r, c, *rest = row
        seed, task, status = (*rest, *(None, "T", "TERMINATED")[len(rest):])
        out.append({"group": g, "status": status, "episode_return": r, "episode_cost": c, "cost_limit": 2.0,
                    "seed": i % 2 if seed is None else seed, "task": task})
    return pd.DataFrame(out)


def _searched(algos, trials=None):
    summary = pd.DataFrame({"n_seeds": [3], "return_mean": [1.0], "cost_mean": [1.0], "feasible": [True]})
    done = pd.DataFrame({"status": ["TERMINATED"] * 4})
    return {a: (done if trials is None else trials.get(a, done), summary, 1000) for a in algos}


def test_the_comparison_ranks_tuned_and_default_and_says_whether_tuning_changed_it():
    # Defaults: A feasible (1.0), B infeasible (5.0): A > B. Tuned: B feasible at 3.0, A at 2.0: B > A.
    trials = _confirmation([("A-default", 1.0, 0.0), ("A-default", 1.0, 1.0), ("B-default", 5.0, 9.0),
                            ("B-default", 5.0, 8.0), ("A-tuned1", 2.0, 1.0), ("A-tuned1", 2.0, 0.0),
                            ("B-tuned1", 3.0, 1.0), ("B-tuned1", 3.0, 2.0)])
    winners = {a: [{"config": "c", "fields": {}, "feasible": True, "search": {"return_mean": 4.0}}] for a in "AB"}
    comp = report.comparison(_searched("AB"), winners, trials)
    r = comp["rankings"]["T"]
    assert r["default"] == "A > B" and r["tuned"] == "B > A" and r["changed"]
    a = comp["algorithms"]["A"]
    assert a["gap"][0] == pytest.approx(1.0) and a["curse"] == pytest.approx(2.0) and a["tuned"]["p_feasible"] == 1.0
    assert a["improved"]  # differences 1.0 and 1.0: no spread, the interval is the point, above 0
    assert comp["algorithms"]["B"]["default"]["feasible"] is False and comp["budgets"]["equal"]


def test_ties_failed_seeds_unequal_budgets_and_two_environments_are_reported():
    # A and B tuned overlap (ties); C ran in another environment (the fingerprint split its task): ranked apart.
    trials = _confirmation([("A-tuned1", 1.0, 0.0, 3), ("A-tuned1", 1.2, 0.0, 4),
                            ("A-tuned1", 0.0, 0.0, 5, "T", "ERROR"),
                            ("A-default", 0.9, 0.0, 3), ("A-default", 1.0, 0.0, 4), ("A-default", 1.0, 0.0, 5),
                            ("B-tuned1", 1.1, 0.0, 3), ("B-tuned1", 1.3, 0.0, 4),
                            ("B-default", 0.5, 0.0, 3), ("B-default", 0.6, 0.0, 4),
                            ("C-tuned1", 9.0, 0.0, 3, "T @env:x"), ("C-tuned1", 9.1, 0.0, 4, "T @env:x"),
                            ("C-default", 8.0, 0.0, 3, "T @env:x"), ("C-default", 8.2, 0.0, 4, "T @env:x")])
    winners = {a: [{"config": "c", "fields": {}, "feasible": True, "search": {"return_mean": 1.0}}] for a in "ABC"}
    short = pd.DataFrame({"status": ["TERMINATED"] * 3 + ["ERROR"]})
    comp = report.comparison(_searched("ABC", {"B": short}), winners, trials)
    assert set(comp["rankings"]) == {"T", "T @env:x"} and comp["rankings"]["T"]["tuned"] == "A = B"
    assert comp["rankings"]["T @env:x"]["tuned"] == "C"  # C's 9 is never ranked above A's and B's 1
    assert comp["algorithms"]["A"]["tuned"]["failed_seeds"] == [5] and comp["algorithms"]["A"]["pairs"] == 2
    assert not comp["budgets"]["equal"] and comp["budgets"]["algorithms"]["B"]["env_steps"] == 3000


@pytest.mark.slow
def test_a_tuned_comparison_runs_end_to_end_and_its_registry_round_trips(ray_session, tmp_path, capsys):
    import yaml

    from sweeps.tuned import run_tuned
    from sweeps.tuned_registry import listing

    tp, = cli.make_plan(_args(tmp_path, TUNED))
    assert run_tuned(tp, cli.run_locked) == 0
    out = capsys.readouterr().out
    assert "## Tuned comparison" in out and "Ranking on the fresh seeds" in out
    # The data the run wrote beside its report renders the same report again, without Ray or MLflow.
    from sweeps import followup
    from sweeps.reports import rendered

    here = tmp_path / "rr" / followup.confirmation_name(tp.name)
    assert sorted(p.name for p in (here / "tuned-data").iterdir()) == [
        "confirmation.csv", "search-lac.csv", "search-ppo_lag.csv", "sweep.yaml"]
    rendered.render(here / "tuned-data", tmp_path / "again")
    assert (tmp_path / "again" / "report.md").read_text() == (here / "tuned.md").read_text()
    registry = tmp_path / "registry"
    for algo in ("lac", "ppo_lag"):
        path, = (registry / "lac/PointHazard-v0" / algo).glob("smoke-b2-*.yaml")  # kept by budget, limit, env
        entry = yaml.safe_load(path.read_text())
        assert entry["fresh_seeds"] == [1000, 2000] and entry["search_seeds"] == [0] and entry["fresh"]["n_seeds"] == 2
        # The verdict: the tuned configuration only where the paired test showed it better.
        assert entry["verdict"] in ("improved", "default-stands") and entry["mlflow"]["confirmation_run"]
        assert set(entry["config"] if entry["verdict"] == "improved" else entry["candidate"]) == set(search_space(algo))
        assert isinstance(entry["search_feasible"], bool) and entry["commit_source"].startswith("the search's MLflow")
    # preset: tuned runs each entry: the trial's params are the entry's configuration, or the default.
    plan, = cli.make_plan(_args(tmp_path, "algo: [lac, ppo_lag]\nbudget: smoke\nseeds: 1\npreset: tuned\n",
                                "--name", "from-registry"))
    for t in plan.trials:
        path, = (registry / "lac/PointHazard-v0" / t.algo).glob("smoke-b2-*.yaml")
        entry = yaml.safe_load(path.read_text())
        if entry["verdict"] == "improved":
            assert {k: t.params[k] for k in entry["config"]} == pytest.approx(entry["config"]) and not t.default
        else:
            base = spaces.trial_params(t.task, "smoke", {"algo": t.algo})
            assert {k: t.params[k] for k in entry["candidate"]} == {k: base[k] for k in entry["candidate"]}
    assert listing(registry).count("lac/PointHazard-v0") == 2


def _entry(tmp_path, env: dict | None = None, **change) -> Path:
    """A valid registry entry of ppo_lag on the tiny task (its fingerprint this machine's, with ``env``
    changed in it), changed."""
    import yaml

    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id

    config = {"lr": 0.002, "clip_param": 0.25}
    fp = fingerprint("lac/PointHazard-v0", spaces.trial_params("lac/PointHazard-v0", "smoke", {"algo": "ppo_lag",
                                                                                                 **config}))
    fp = {**fp, **(env or {})}
    scores = {"n_seeds": 2, "return_mean": 1.0, "return_ci": [0.5, 1.5], "cost_mean": 1.0, "cost_ci": [0.0, 2.0],
              "p_feasible": 1.0}
    data = {"task": "lac/PointHazard-v0", "algo": "ppo_lag", "budget": "smoke", "timesteps": 2000, "cost_limit": 2.0,
            "config": config, "search_seeds": [0], "fresh_seeds": [1, 2], "fresh": scores, "default_fresh": scores,
            "search": {"return_mean": 1.2}, "mlflow": {"tracking_uri": "sqlite:///x.db"}, "commit": "abc",
            "fingerprint": fp, "fingerprint_id": fingerprint_id(fp), **change}
    path = tmp_path / "registry" / "lac/PointHazard-v0" / "ppo_lag.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data))
    return path


PRESET = "algo: ppo_lag\nbudget: smoke\nseeds: 1\npreset: tuned\n"


def test_preset_tuned_reads_a_good_entry(tmp_path):
    _entry(tmp_path)
    plan, = cli.make_plan(_args(tmp_path, PRESET))
    assert plan.trials[0].params["lr"] == 0.002 and plan.trials[0].params["clip_param"] == 0.25
    # The sweep's own set wins over the entry (the entry sits where the defaults were).
    plan, = cli.make_plan(_args(tmp_path, PRESET + "set: {lr: 0.004}\n", "--name", "x2"))
    assert plan.trials[0].params["lr"] == 0.004 and plan.trials[0].params["clip_param"] == 0.25
    from sweeps.tuned_registry import listing

    assert "lac/PointHazard-v0 ppo_lag @ smoke (limit 2): clip_param=0.25, lr=0.002" in listing(tmp_path / "registry")
    assert "nothing feasible" not in listing(tmp_path / "registry")
    assert cli.main(["registry", str(tmp_path / "registry")]) == 0
    _entry(tmp_path, search_feasible=False)  # a search without a feasible configuration: said beside it
    assert "its search had nothing feasible: the least costly" in listing(tmp_path / "registry")


def test_an_entry_of_another_environment_is_refused_naming_the_difference(tmp_path):
    _entry(tmp_path, env={"mujoco": "0.0.1-other", "envs": 3})
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, PRESET))
    assert "was tuned in another environment: envs 3 vs 1; mujoco 0.0.1-other vs" in str(e.value), str(e.value)


@pytest.mark.parametrize("tamper,needle", [
    (lambda p: p.write_text("task: [unclosed\n"), "ppo_lag.yaml"),
    (lambda p: p.write_text(p.read_text() + "hostile: 1\n"), "hostile: Extra inputs are not permitted"),
    (lambda p: p.write_text(p.read_text().replace("clip_param: 0.25", "clip_param: -3.0")), "config.clip_param"),
    (lambda p: p.write_text(p.read_text().replace("mujoco: ", "mujoco: 0.0.1-other #")),
     "is not its fingerprint's ("),
    (lambda p: p.write_text(p.read_text().replace("budget: smoke", "budget: quick")), "was tuned at budget quick"),
    (lambda p: p.unlink(), "has no entry for ppo_lag on lac/PointHazard-v0"),
])
def test_a_tampered_or_missing_entry_is_refused_before_ray_in_one_line(tmp_path, tamper, needle):
    tamper(_entry(tmp_path))
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, PRESET))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


PBT_TUNED = """task: lac/PointHazard-v0
budget: smoke
algo: [lac, ppo_lag, sac_lag]
eval_episodes: 0
tune: {searcher: pbt, pbt: {members: 4, interval: 1000}, confirm_seeds: 2}
"""


def test_a_pbt_tuned_comparison_gives_every_algorithm_the_same_population_and_confirms_schedules(tmp_path, capsys):
    """``tune: {searcher: pbt}``: each algorithm a population of the same size over its changeable
    fields at the same env steps; its best member's schedule (read back with the trials) confirmed
    beside its default."""
    import json

    from lac_rllib.algorithms.registry import changeable_space
    from sweeps.tuned import budget_of, confirmation_sweep, print_tuned_plan, search_winners

    tp, = cli.make_plan(_args(tmp_path, PBT_TUNED))
    assert {a: budget_of(p) for a, p in tp.searches.items()} == {a: (4, 1, 2000) for a in ("lac", "ppo_lag", "sac_lag")}
    assert all(p.pbt == (1000,) and p.seeds == (0, 1, 2, 3) for p in tp.searches.values())
    assert all(set(p.sweep.search) == set(changeable_space(a)) for a, p in tp.searches.items())
    assert {"actor_lr", "critic_lr", "nu_lr"} <= set(tp.searches["lac"].sweep.search)  # LAC's rates change mid-run
    print_tuned_plan(tp)
    assert "population-based training ranked by the one feasibility rule" in capsys.readouterr().out
    schedule = [[0, {"lr": 0.001}], [1000, {"lr": 0.0012}]]
    trials = pd.DataFrame({"trial_id": ["a", "b", "c"], "config": ["x", "y", "z"], "seed": [0, 1, 2],
                           "episode_return": [9.0, 5.0, 20.0], "episode_cost": [1.0, 0.5, 9.0],
                           "cost_limit": [2.0, 2.0, 2.0], "schedule": [json.dumps(schedule), "[[0, {}]]", "[[0, {}]]"]})
    winner, = search_winners(tp, "ppo_lag", trials)  # the feasible best: c is over its limit
    assert winner["schedule"] == [{"at": 0, "set": {"lr": 0.001}}, {"at": 1000, "set": {"lr": 0.0012}}]
    assert winner["feasible"] and winner["search"]["return_mean"] == 9.0
    over = trials.assign(episode_cost=[5.0, 3.0, 9.0])
    least, = search_winners(tp, "ppo_lag", over)  # none feasible: the least costly, said
    assert least["config"] == "y" and not least["feasible"]
    cfile = confirmation_sweep(tp, {"ppo_lag": [winner]})
    assert cfile.groups["ppo_lag-tuned1"].schedule[1].at == 1000 and cfile.groups["ppo_lag-default"].schedule is None


@pytest.mark.parametrize("text,needle", [
    (PBT_TUNED.replace("pbt: {members: 4, interval: 1000}", "num_samples: 4"), "num_samples with searcher pbt"),
    (PBT_TUNED.replace("searcher: pbt, ", ""), "tune.pbt: pbt with searcher tpe"),
    (PBT_TUNED.replace("interval: 1000", "interval: 5000"), "not shorter than the budget"),
])
def test_bad_pbt_tune_sections_are_refused_in_one_line(tmp_path, text, needle):
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, text))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)
