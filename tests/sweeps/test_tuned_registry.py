"""The registry of tuned configurations keeps only what was shown better, and loses nothing
(sweeps/tuned_registry.py): a verdict per algorithm from the paired test, entries kept per budget,
limit and environment, a replacement's old entry kept, a smoke comparison out of the repository's
registry unless asked; ``preset: tuned`` refuses an entry of another limit and checks every trial's
environment after its group's and grid's fields. Comparisons are faked (no Ray): ``write_entries``
is given a comparison as sweeps/reports/tuned.py ``comparison`` returns it."""

import json
from pathlib import Path

import pandas as pd
import pytest
import yaml

from lac_rllib.algorithms.registry import search_space
from sweeps import run as cli
from sweeps import spaces
from sweeps.tuned_registry import DEFAULT_REGISTRY, listing, read_entry, write_entries

TASK = "lac/PointHazard-v0"
SMOKE_TUNED = f"""task: {TASK}
budget: smoke
algo: [lac, ppo_lag]
eval_episodes: 1
tune: {{num_samples: 2, seeds: 1, confirm_seeds: 2}}
"""
PRESET = "algo: ppo_lag\nbudget: smoke\nseeds: 1\npreset: tuned\n"
FIELDS = {"lac": {"langevin_steps": 30, "temperature": 0.0005}, "ppo_lag": {"lr": 0.002, "clip_param": 0.25}}
FRESH = (1000, 2000, 3000)


def _args(tmp_path, text, *extra, registry: bool = True, name: str = "s.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return cli.parse_args(["--config", str(path), "--experiment", "test", "--tracking-uri",
                           f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr"),
                           *(["--registry", str(tmp_path / "registry")] if registry else []), *extra])


def _figures(returns, limit=2.0) -> dict:
    """A group's figures on the fresh seeds, as sweeps/reports/tuned.py ``_figures`` gives them."""
    n = len(returns)
    mean = sum(returns) / n
    return {"n_seeds": n, "n_feasible": n, "return": (mean, mean - 0.1, mean + 0.1), "cost": (0.0, 0.0, 0.0),
            "p_feasible": 1.0, "p_feasible_ci": (1.0, 0.44, 1.0), "violation": 0.0, "feasible": True,
            "limit": limit, "seeds": list(FRESH[:n]), "failed_seeds": [], "tasks": [TASK],
            "by_seed": dict(zip(FRESH, returns))}


def _comparison(tp, better: dict, shift: float = 0.0):
    """``write_entries``' arguments for ``tp``: per algorithm (``better``: algo → whether the paired test
    showed tuning better) a comparison, its winner, the searches' parent runs (faked on disk)."""
    algos = {}
    for algo, improved in better.items():
        default = [0.5, 0.6, 0.7]
        tuned = [r + (0.3 if improved else -0.3) + shift for r in default]
        gap = (tuned[0] - default[0], 0.1, 0.5) if improved else (tuned[0] - default[0], -0.5, -0.1)
        algos[algo] = {"tuned": _figures(tuned), "default": _figures(default), "gap": gap, "pairs": 3,
                       "improved": improved, "p_improvement": 1.0 if improved else 0.0, "apart": False}
    winners = {a: [{"config": "c", "fields": FIELDS[a], "feasible": True, "search": {"return_mean": 1.0}}]
               for a in better}
    for algo, plan in tp.searches.items():
        folder = Path(plan.storage) / plan.name
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "sweep.json").write_text(json.dumps({"parent_run_id": f"search-{algo}"}))
    trials = pd.DataFrame({"seed": list(FRESH)})
    return {"algorithms": algos}, winners, "confirmation-run", dict(tp.searches), trials


def _snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_smoke_comparison_without_registry_leaves_the_shipped_entries_byte_identical(tmp_path, capsys):
    before = _snapshot(DEFAULT_REGISTRY)
    assert before, "the repository ships entries"
    tp, = cli.make_plan(_args(tmp_path, SMOKE_TUNED, registry=False))  # 2 samples × 1 seed, no --registry
    written = write_entries(tp, *_comparison(tp, {"lac": True, "ppo_lag": True}))
    assert _snapshot(DEFAULT_REGISTRY) == before
    assert len(written) == 2 and all((tmp_path / "rr") in p.parents for p in written), written
    out = capsys.readouterr().out
    assert "a smoke budget writes into a registry only when --registry names one: the entries go to" in out


def test_a_worse_tuned_configuration_writes_that_the_default_stands_and_preset_tuned_runs_the_default(
        tmp_path, capsys):
    tp, = cli.make_plan(_args(tmp_path, SMOKE_TUNED))
    written = write_entries(tp, *_comparison(tp, {"lac": True, "ppo_lag": False}))
    entries = {yaml.safe_load(p.read_text())["algo"]: yaml.safe_load(p.read_text()) for p in written}
    worse, better = entries["ppo_lag"], entries["lac"]
    assert worse["verdict"] == "default-stands" and worse["config"] == {} and worse["candidate"] == FIELDS["ppo_lag"]
    assert better["verdict"] == "improved" and better["config"] == FIELDS["lac"] and better["candidate"] is None
    assert worse["gap"] == pytest.approx([-0.3, -0.5, -0.1]) and worse["by_seed"]["default"] == {
        1000: 0.5, 2000: 0.6, 3000: 0.7}
    assert worse["constraints"] == {"cost": 2.0} and worse["searcher"] == "tpe" and worse["num_samples"] == 2
    assert set(worse["search_space"]) == set(search_space("ppo_lag")) and worse["random_start"] in (None, 1)
    assert "paired" in worse["intervals"] and "mean" in worse["intervals"]
    assert worse["commit_source"].startswith("git HEAD when the entry was written")  # the fake search has no run
    assert "ppo_lag on lac/PointHazard-v0: tuning did not beat the default" in capsys.readouterr().out
    # preset: tuned runs ppo_lag's default, says so in one line naming the entry, and lac's tuned configuration.
    plan, = cli.make_plan(_args(tmp_path, "algo: [lac, ppo_lag]\nbudget: smoke\nseeds: 1\npreset: tuned\n",
                                "--name", "from-registry"))
    out = capsys.readouterr().out
    said = [line for line in out.splitlines() if "verdict default-stands" in line]
    assert len(said) == 1 and str(written[[*entries].index("ppo_lag")]) in said[0], out
    by_algo = {t.algo: t.params for t in plan.trials}
    default = spaces.trial_params(TASK, "smoke", {"algo": "ppo_lag"})
    assert {k: by_algo["ppo_lag"][k] for k in FIELDS["ppo_lag"]} == {k: default[k] for k in FIELDS["ppo_lag"]}
    assert {k: by_algo["lac"][k] for k in FIELDS["lac"]} == FIELDS["lac"]


def _entry(registry: Path, cost_limit: float = 2.0, legacy: bool = False, **change) -> Path:
    """A ppo_lag entry on the tiny task at the smoke budget, tuned in this machine's environment."""
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id

    config = FIELDS["ppo_lag"]
    fp = fingerprint(TASK, spaces.trial_params(TASK, "smoke", {"algo": "ppo_lag", **config}))
    scores = {"n_seeds": 2, "return_mean": 1.0, "return_ci": [0.5, 1.5], "cost_mean": 1.0, "cost_ci": [0.0, 2.0],
              "p_feasible": 1.0}
    data = {"task": TASK, "algo": "ppo_lag", "budget": "smoke", "timesteps": 2000, "cost_limit": cost_limit,
            "config": config, "search_seeds": [0], "fresh_seeds": [1, 2], "fresh": scores, "default_fresh": scores,
            "search": {"return_mean": 1.2}, "mlflow": {"tracking_uri": "sqlite:///x.db"}, "commit": "abc",
            "fingerprint": fp, "fingerprint_id": fingerprint_id(fp), **change}
    path = (registry / TASK / "ppo_lag.yaml" if legacy else
            registry / TASK / "ppo_lag" / f"smoke-b{cost_limit:g}-{fingerprint_id(fp)}.yaml")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("extra,needle", [
    ("cost_limits: [2, 5]\n", "was tuned at limit 2, trial ppo_lag-s-PointHazard-v0-b5 runs at 5; accepted: an entry "
                              "tuned at 5, or tuned_limit: 2"),
    ("set: {cost_limit: 5}\n", "was tuned at limit 2, trial"),
    ("cost_limits: [2, 5]\ntuned_limit: 3\n", "tuned_limit 3: the registry"),
])
def test_preset_tuned_at_another_limit_is_refused_in_one_line(tmp_path, extra, needle):
    _entry(tmp_path / "registry", legacy=True)  # the layout both read
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, PRESET + extra))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_tuned_limit_says_explicitly_which_entry_every_rung_starts_from(tmp_path):
    _entry(tmp_path / "registry", legacy=True)  # the layout both read
    plan, = cli.make_plan(_args(tmp_path, PRESET + "cost_limits: [2, 5]\ntuned_limit: 2\n"))
    assert [t.params["cost_limit"] for t in plan.trials] == [2.0, 5.0]
    assert all(t.params["lr"] == 0.002 and t.params["clip_param"] == 0.25 for t in plan.trials)
    with pytest.raises(ValueError) as e:  # without preset: tuned it would say nothing: refused
        cli.make_plan(_args(tmp_path, "algo: ppo_lag\nbudget: smoke\ntuned_limit: 2\n", "--name", "x2"))
    assert "s.yaml:3: tuned_limit 2 without preset: tuned" in str(e.value) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("extra", [
    "groups:\n  plain: {}\n  wide: {set: {num_envs_per_env_runner: 2}}\n",
    "grid: {num_envs_per_env_runner: [1, 2]}\n",
])
def test_a_group_or_grid_changing_the_env_count_is_refused_by_the_per_trial_fingerprint(tmp_path, extra):
    _entry(tmp_path / "registry", legacy=True)  # the layout both read
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, PRESET + extra))
    assert "was tuned in another environment: envs 1 vs 2" in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_old_format_entries_still_read_and_list_their_missing_fields_as_unknown(tmp_path):
    import shutil

    old = sorted(DEFAULT_REGISTRY.rglob("history/*.yaml"))  # the first shipped ones, written before the verdict
    assert len(old) == 4
    for path in old:  # each back in its algorithm's folder of a registry of its own
        dest = tmp_path / "old" / path.relative_to(DEFAULT_REGISTRY).parent.parent / "entry.yaml"
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, dest)
    listed = listing(tmp_path / "old")
    assert listed.count("unknown (written before they were recorded): ") == 4, listed
    assert "lac/PointHazard-v0 lac @ quick (limit 2): langevin_steps=61" in listed and "verdict unknown" in listed
    shipped = listing(DEFAULT_REGISTRY)  # the re-run's: every field recorded
    assert "unknown" not in shipped and shipped.count("verdict default-stands") == 4, shipped
    # An entry in the earlier layout (tuned/<task>/<algo>.yaml) without the new fields still runs.
    _entry(tmp_path / "registry", legacy=True)
    plan, = cli.make_plan(_args(tmp_path, PRESET))
    assert plan.trials[0].params["lr"] == 0.002 and plan.trials[0].params["clip_param"] == 0.25
    text = listing(tmp_path / "registry")
    assert "verdict unknown" in text and "searcher, samples, random start, search space, per-seed scores" in text


def test_the_shipped_trpo_lag_entry_tuned_worse_runs_the_default(tmp_path, capsys):
    plan, = cli.make_plan(_args(tmp_path, "algo: trpo_lag\nbudget: quick\nseeds: 1\npreset: tuned\n", registry=False))
    default = spaces.trial_params(TASK, "quick", {"algo": "trpo_lag"})
    assert plan.trials[0].params == default
    out = capsys.readouterr().out
    assert "trpo_lag/quick-b2-493ce206c175.yaml: tuning trpo_lag on lac/PointHazard-v0" in out
    assert "(verdict default-stands): its trials run the default" in out


def test_a_replacement_keeps_the_old_entry_and_says_so(tmp_path, capsys):
    registry = tmp_path / "registry"
    tp, = cli.make_plan(_args(tmp_path, SMOKE_TUNED))
    first, = write_entries(tp, *_comparison(tp, {"ppo_lag": True}))
    old = first.read_bytes()
    legacy = _entry(registry, legacy=True)  # the earlier layout's entry of the same budget, limit and environment
    legacy_old = legacy.read_bytes()
    capsys.readouterr()
    second, = write_entries(tp, *_comparison(tp, {"ppo_lag": True}, shift=0.05))
    assert second == first and second.read_bytes() != old and not legacy.exists()
    kept = sorted((first.parent / "history").glob("*.yaml"))
    assert sorted(p.read_bytes() for p in kept) == sorted([old, legacy_old])
    out = capsys.readouterr().out
    assert out.count(f"registry: {first} replaces an entry tuned under the same budget, limit and environment") == 2
    assert "the old entry is kept as" in out and "2 replaced entries kept in history/" in listing(registry)
    # Another limit is another entry: nothing replaced.
    other = _entry(registry, cost_limit=3.0)
    assert other.exists() and first.exists() and len(list(registry.rglob("*.yaml"))) == 4


def test_the_commit_is_the_one_the_search_ran_at(tmp_path):
    from mlflow import MlflowClient

    from sweeps.tuned_registry import COMMIT_AT_WRITE, COMMIT_FROM_SEARCH, search_commit

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = MlflowClient(uri)
    run = client.create_run(client.create_experiment("e")).info.run_id
    client.log_param(run, "git_commit", "0123456789abcdef")
    assert search_commit(uri, run) == ("0123456789abcdef", COMMIT_FROM_SEARCH)
    assert search_commit(uri, "no-such-run")[1] == COMMIT_AT_WRITE
    assert search_commit(f"sqlite:///{tmp_path / 'absent.db'}", run)[1] == COMMIT_AT_WRITE
    assert not (tmp_path / "absent.db").exists()


def test_an_entry_tuned_with_a_limit_per_constraint_is_kept_by_them_and_refused_elsewhere(tmp_path):
    """An entry tuned with constraints {hazard: 2, lane: 10} carries them (its key names them); preset:
    tuned starts trials at those limits from it, and refuses other limits, and a trial on the summed
    cost (whose environment differs: the fingerprint names the constraints) in one line each."""
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id
    from sweeps.tuned_registry import entry_key

    task, limits = "lac/PointTwoCosts-v0", {"hazard": 2.0, "lane": 10.0}
    config = FIELDS["ppo_lag"]
    fp = fingerprint(task, spaces.trial_params(task, "smoke", {"algo": "ppo_lag", "constraints": limits, **config}))
    key = entry_key("smoke", 0.0, fingerprint_id(fp), limits)
    assert key == f"smoke-hazard2-lane10-{fingerprint_id(fp)}"
    scores = {"n_seeds": 2, "return_mean": 1.0, "return_ci": [0.5, 1.5], "cost_mean": -1.0, "cost_ci": [-2.0, 0.0],
              "p_feasible": 1.0}
    path = tmp_path / "registry" / task / "ppo_lag" / f"{key}.yaml"
    path.parent.mkdir(parents=True)
    path.write_text(yaml.safe_dump({
        "task": task, "algo": "ppo_lag", "budget": "smoke", "timesteps": 2000, "cost_limit": 0.0, "config": config,
        "search_seeds": [0], "fresh_seeds": [1, 2], "fresh": scores, "default_fresh": scores, "search": {},
        "mlflow": {"tracking_uri": "sqlite:///x.db"}, "commit": "abc", "fingerprint": fp,
        "fingerprint_id": fingerprint_id(fp), "constraints": limits}))
    base = f"task: {task}\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\npreset: tuned\n"
    plan, = cli.make_plan(_args(tmp_path, base + "constraints: {hazard: 2, lane: 10}\n"))
    assert all(t.params["lr"] == 0.002 and t.params["constraints"] == limits for t in plan.trials)
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, base + "constraints: {hazard: 2, lane: 5}\n", "--name", "x2"))
    assert "was tuned at limits hazard 2, lane 10, trial" in str(e.value) and "runs at hazard 2, lane 5" in str(e.value)
    with pytest.raises(ValueError) as e:
        cli.make_plan(_args(tmp_path, base + "set: {cost_limit: 0}\n", "--name", "x3"))
    assert "was tuned with a limit per constraint (hazard 2, lane 10), trial" in str(e.value)
    assert "runs one limit 0 on the summed cost" in str(e.value) and "\n" not in str(e.value), str(e.value)


SCHEDULE = [{"at": 0, "set": {"lr": 0.002, "clip_param": 0.25}}, {"at": 1000, "set": {"lr": 0.004, "clip_param": 0.2}}]


def test_a_pbt_winners_schedule_is_what_preset_tuned_replays_below_the_trials_own_fields(tmp_path):
    _entry(tmp_path / "registry", verdict="improved", schedule=SCHEDULE, searcher="pbt")
    plan, = cli.make_plan(_args(tmp_path, PRESET + "groups:\n  plain: {}\n  own: {set: {clip_param: 0.15}}\n"))
    plain, own = plan.trials
    assert plain.schedule == [[0, {"lr": 0.002, "clip_param": 0.25}], [1000, {"lr": 0.004, "clip_param": 0.2}]]
    assert plain.params["lr"] == 0.002 and not plain.default
    assert own.schedule == [[0, {"lr": 0.002}], [1000, {"lr": 0.004}]] and own.params["clip_param"] == 0.15
    assert "its schedule's at 1,000 env steps" in listing(tmp_path / "registry")


def test_a_pbt_schedule_whose_default_stands_is_not_replayed(tmp_path):
    _entry(tmp_path / "registry", verdict="default-stands", schedule=SCHEDULE, config={}, searcher="pbt")
    plan, = cli.make_plan(_args(tmp_path, PRESET))
    assert plan.trials[0].schedule is None and plan.trials[0].params["lr"] != 0.004


@pytest.mark.parametrize("bad, needle", [
    ([{"at": 0, "set": {"hidden": [8, 8]}}], "schedule.0.set.hidden: hidden is not a field ppo_lag can change"),
    ([{"at": 0, "set": {"lr": -1.0}}], "schedule.0.set.lr"),
    ([{"at": 500, "set": {"lr": 0.1}}, {"at": 100, "set": {"lr": 0.2}}], "strictly ascending"),
])
def test_a_registry_schedule_is_read_as_untrusted_input(tmp_path, bad, needle):
    path = _entry(tmp_path / "registry", verdict="improved", schedule=bad, searcher="pbt")
    with pytest.raises(ValueError) as e:
        read_entry(path)
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)
