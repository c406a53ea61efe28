"""The env fingerprint (lac_rllib/tasks/fingerprint.py): what it reads, and that no report ranks
runs of different environments together (sweeps/reports/results.py) nor a sweep resumes in another."""

import json
from pathlib import Path

import pandas as pd
import pytest

from lac_rllib.tasks import fingerprint as fpm
from sweeps import run as cli
from sweeps import spaces
from sweeps.reports.report import summarize
from sweeps.reports.results import ENV_COLUMN, ENV_JSON_COLUMN, environment_note, split_environments


def _fp(**params):
    return fpm.fingerprint("lac/PointHazard-v0", spaces.trial_params("lac/PointHazard-v0", "smoke", params))


def test_the_fingerprint_reads_the_envs_the_filter_the_simulator_and_the_cpu_where_a_dtype_asks():
    base = _fp()
    assert base["task"] == "lac/PointHazard-v0" and base["episode_steps"] == 100 and base["mujoco"]
    assert base["episode_cost_discount"] == 1.0 and base["cpu_bf16"] is None  # no dtype left to the CPU
    for change, key in [({"num_envs_per_env_runner": 2}, "envs"), ({"obs_clip": 3.0}, "obs_clip"),
                        ({"obs_normalization": False}, "obs_normalization")]:
        other = _fp(**change)
        assert other[key] != base[key] and fpm.fingerprint_id(other) != fpm.fingerprint_id(base), key
    assert fpm.fingerprint_id(_fp(cost_limit=0.0)) == fpm.fingerprint_id(base)  # a ladder's limits stay comparable
    assert isinstance(_fp(algo="sac_lag", critic_dtype="auto")["cpu_bf16"], bool)
    assert fpm.differences(base, {**base, "mujoco": "0.1", "envs": 7}) == f"envs {base['envs']} vs 7; mujoco " \
                                                                         f"{base['mujoco']} vs 0.1"


def _trials(versions, algos=None, fps=None):
    rows = []
    for i, mujoco in enumerate(versions):
        fp = {**(fps[i] if fps else _fp()), "mujoco": mujoco}
        algo = algos[i] if algos else "lac"
        rows.append({"group": algo, "param": "", "value": None, "task": "lac/PointHazard-v0", "config": algo,
                     "algo": algo,
                     "seed": i, "default": True, "status": "TERMINATED", "episode_return": float(i),
                     "episode_cost": 0.0, "cost_limit": 2.0, "feasible": 1.0, "objective": float(i), "score": "train",
                     ENV_COLUMN: fpm.fingerprint_id(fp), ENV_JSON_COLUMN: json.dumps(fp)})
    return pd.DataFrame(rows)


def test_trials_of_two_simulator_versions_are_split_with_a_note_naming_the_difference():
    split = split_environments(_trials(["3.3.0", "3.3.0", "3.2.7", "3.2.7"]))
    tasks = sorted(split["task"].unique())
    assert len(tasks) == 2 and all(t.startswith("lac/PointHazard-v0 @env:") for t in tasks)
    assert len(summarize(split)) == 2  # one row per environment, never one mean over both
    note = environment_note(split)
    assert "`lac/PointHazard-v0` ran in 2 environments" in note and "mujoco 3.3.0 vs 3.2.7" in note, note
    one = split_environments(_trials(["3.3.0", "3.3.0"]))
    assert set(one["task"]) == {"lac/PointHazard-v0"} and environment_note(one) == ""


def test_each_algorithm_at_its_own_filter_is_ranked_with_the_others_but_one_algorithm_in_two_is_split():
    """RESPO's reference runs without the observation filter: a comparison still ranks it beside LAC.
    Two runs of one algorithm that differ in their envs are split, with the note naming the envs."""
    lac, respo = _fp(), _fp(algo="respo", obs_normalization=False)
    together = split_environments(_trials(["3.3.0"] * 2, ["lac", "respo"], [lac, respo]))
    assert set(together["task"]) == {"lac/PointHazard-v0"} and environment_note(together) == ""
    assert len(summarize(together)) == 2
    two = _fp(num_envs_per_env_runner=2)
    split = split_environments(_trials(["3.3.0"] * 3, ["lac", "lac", "respo"], [lac, two, respo]))
    assert split["task"].nunique() == 3 and "@env:" in split["task"].iloc[0], split["task"].tolist()
    note = environment_note(split)
    assert "envs 1 vs 2" in note and "obs_normalization" not in note, note


def test_the_note_names_the_default_environment_first_whatever_order_the_trials_finished_in():
    """MLflow lists child runs in the order they ran: the note must not follow it."""
    rows = _trials(["3.3.0"] * 2, fps=[_fp(), _fp(num_envs_per_env_runner=2)])
    rows["default"], rows["trial_id"] = [True, False], ["lac-envs=1-s0", "lac-envs=2-s0"]
    for order in (rows, rows.iloc[::-1]):
        note = environment_note(split_environments(order.reset_index(drop=True)))
        assert "envs 1 vs 2" in note, note


def test_a_resume_under_a_changed_environment_is_refused(tmp_path, monkeypatch):
    from sweeps.record import checked_sweep_dir, write_record

    argv = ["--space", "smoke", "--budget", "smoke", "--seeds", "1", "--experiment", "test",
            "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")]
    plan, = cli.make_plan(cli.parse_args(argv))
    write_record(Path(plan.storage) / plan.name, plan, "parent-run")
    assert checked_sweep_dir(cli.make_plan(cli.parse_args([*argv, "--resume"]))[0])  # the same environment resumes
    real = fpm.runtime_versions
    monkeypatch.setattr(fpm, "runtime_versions", lambda: {**real(), "mujoco": "9.9.9"})
    with pytest.raises(ValueError) as e:
        checked_sweep_dir(cli.make_plan(cli.parse_args([*argv, "--resume"]))[0])
    assert "was started with other settings" in str(e.value) and "mujoco" in str(e.value) and "vs 9.9.9" in str(e.value)


@pytest.mark.slow
def test_two_smoke_runs_differing_in_envs_per_runner_are_split_in_the_summary(ray_session, tmp_path):
    from mlflow.tracking import MlflowClient

    from sweeps.sweep import run_sweep

    path = tmp_path / "envs.yaml"
    path.write_text("budget: smoke\nseeds: 1\neval_episodes: 0\nalgo: ppo_lag\n"
                    "grid: {num_envs_per_env_runner: [1, 2]}\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(path), "--experiment", "test", "--tracking-uri",
                                          f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "rr")]))
    assert run_sweep(plan, Path(plan.storage) / plan.name, "test-commit") == 0
    client = MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    runs = client.search_runs([client.get_experiment_by_name("test").experiment_id])
    parent = next(r for r in runs if r.data.tags.get("lac.sweep") == "1")
    children = [r for r in runs if "mlflow.parentRunId" in r.data.tags]
    assert len({c.data.tags["lac.env_fingerprint"] for c in children}) == 2
    note = parent.data.tags["mlflow.note.content"]
    assert "**Not ranked together**" in note and "envs 1 vs 2" in note, note[:2000]
    summary = Path(client.download_artifacts(parent.info.run_id, "summary/summary.csv", str(tmp_path))).read_text()
    assert summary.count("@env:") == 2


def test_constraints_held_apart_are_in_the_fingerprint_and_their_limits_are_not():
    base = fpm.fingerprint("SafetyPointGoal2-v0", {})
    two = fpm.fingerprint("SafetyPointGoal2-v0", {"constraints": {"vases": 5, "hazards": 10}})
    other_limits = fpm.fingerprint("SafetyPointGoal2-v0", {"constraints": {"vases": 1, "hazards": 30}})
    assert "constraints" not in base and two["constraints"] == ["hazards", "vases"]
    assert fpm.fingerprint_id(two) == fpm.fingerprint_id(other_limits) != fpm.fingerprint_id(base)
    assert "constraints None vs ['hazards', 'vases']" in fpm.differences(base, two)
