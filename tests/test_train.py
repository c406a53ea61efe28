"""lac-train: the command as a user runs it (tiny budget), and stop → resume of a run."""

import json
import subprocess
import sys

import pytest

import lac_rllib
from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.algorithms.registry import algos_text
from lac_rllib.constrained.algorithm import CHECKPOINT_FORMAT
from lac_rllib.constrained.metrics import LANGEVIN_AT_BOUND
from lac_rllib.train import CONFIG, PROGRESS, check_output, run_config, train

TINY = ["--set", "env_steps_per_iteration=500", "--set", "replay_capacity=2000", "--set", "random_iterations=1"]


def _lac_train(*args, cwd):
    return subprocess.run([sys.executable, "-m", "lac_rllib.train", "--task", "lac/PointHazard-v0", *args],
                          cwd=cwd, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_lac_train_command_runs_and_refuses_to_mix_runs(tmp_path):
    out = tmp_path / "run"
    proc = _lac_train("--timesteps", "1000", "--output", str(out), *TINY, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["env_steps"] == 1000 and summary["iterations"] == 2 and summary["task"] == "lac/PointHazard-v0"
    assert (out / "checkpoint" / "rllib_checkpoint.json").exists()
    rows = [json.loads(line) for line in (out / PROGRESS).read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2] and LANGEVIN_AT_BOUND in rows[-1]
    # The same output again without --resume: refused before Ray starts, nothing appended.
    again = _lac_train("--timesteps", "1000", "--output", str(out), *TINY, cwd=tmp_path)
    assert again.returncode == 2 and "pass --resume" in again.stderr
    assert "Started a local Ray instance" not in again.stdout + again.stderr
    # --resume with other settings names the difference.
    other = _lac_train("--timesteps", "1000", "--output", str(out), *TINY, "--set", "beta=1.0", "--resume",
                       cwd=tmp_path)
    assert other.returncode == 2 and "beta=0.0 (now 1.0)" in other.stderr
    assert len((out / PROGRESS).read_text().splitlines()) == 2
    # A checkpoint another lac-rllib version wrote (its classes may live elsewhere) is refused in one line.
    meta_file = out / "checkpoint" / "rllib_checkpoint.json"
    meta_file.write_text(json.dumps({**json.loads(meta_file.read_text()), "lac_rllib_version": "0.1.0"}))
    old = _lac_train("--timesteps", "1000", "--output", str(out), *TINY, "--resume", cwd=tmp_path)
    assert old.returncode == 2 and "version mismatch: written by lac-rllib 0.1.0" in old.stderr, old.stderr[-500:]


class _Stop(Exception):
    pass


@pytest.mark.slow
def test_a_stopped_run_resumes_from_its_last_checkpoint(ray_session, tmp_path):
    out = str(tmp_path / "run")
    config = LACConfig.build("lac/PointHazard-v0", 0, {"env_steps_per_iteration": 500, "replay_capacity": 2000,
                                                     "random_iterations": 1}, timesteps=2500)

    def stop_at_iteration_4(line, **_):
        if line.startswith("iter    4"):
            raise _Stop  # as a kill would: after iteration 4's progress line, before its checkpoint

    with pytest.raises(_Stop):
        train(config, 2500, out, log=stop_at_iteration_4, checkpoint_every=3)
    assert len((tmp_path / "run" / PROGRESS).read_text().splitlines()) == 4
    summary = train(config, 2500, out, log=lambda *a, **k: None, resume=True)
    rows = [json.loads(line) for line in (tmp_path / "run" / PROGRESS).read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2, 3, 4, 5]  # iteration 4 was trained again, logged once
    assert [r["env_steps"] for r in rows] == [500, 1000, 1500, 2000, 2500]
    assert summary["env_steps"] == 2500 and summary["iterations"] == 5
    assert all(rows[i]["time_s"] < rows[i + 1]["time_s"] for i in range(4))


@pytest.mark.slow
def test_resuming_a_finished_run_says_so_and_returns_its_summary(ray_session, tmp_path):
    """--resume of a run that already reached --timesteps trains nothing: it says the run is
    finished and returns the summary the run ended with (its last row, its checkpoint)."""
    out = str(tmp_path / "run")
    config = LACConfig.build("lac/PointHazard-v0", 0, {"env_steps_per_iteration": 500, "replay_capacity": 2000,
                                                     "random_iterations": 1}, timesteps=1000)
    first = train(config, 1000, out, log=lambda *a, **k: None)
    progress = (tmp_path / "run" / PROGRESS).read_text()
    checkpoint_files = {p: p.stat().st_mtime_ns for p in (tmp_path / "run" / "checkpoint").rglob("*")}
    lines = []
    again = train(config, 1000, out, log=lambda line, **_: lines.append(line), resume=True)
    assert not any(line.startswith("iter ") for line in lines), lines  # nothing trained
    assert any("is finished" in line and "1000 of 1000 env steps" in line for line in lines), lines
    assert (tmp_path / "run" / PROGRESS).read_text() == progress
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "run" / "checkpoint").rglob("*")} == checkpoint_files

    def without_wall_time(summary):  # the first run's wall time also counts its final checkpoint's write
        return json.dumps({k: v for k, v in summary.items() if k != "wall_time_s"}, default=str)

    assert without_wall_time(again) == without_wall_time(first)
    assert (again["env_steps"], again["iterations"]) == (1000, 2)
    assert again["wall_time_s"] == round(json.loads(progress.splitlines()[-1])["time_s"], 2) <= first["wall_time_s"]


def test_resume_may_change_speed_fields_only(tmp_path):
    """A run started with other speed-only values resumes; a change of what is learned is refused,
    naming the field."""
    config = LACConfig.build("lac/PointHazard-v0", 0, {}, timesteps=1000)
    started = {**run_config(config), "langevin_fused": False, "num_envs_per_env_runner": 2, "torch_threads": 2}
    (tmp_path / CONFIG).write_text(json.dumps(started))
    _fake_checkpoint(tmp_path, config)  # what SafeAlgorithm writes
    check_output(str(tmp_path),
                 LACConfig.build("lac/PointHazard-v0", 0, {"num_envs_per_env_runner": 4}, timesteps=1000), resume=True)
    with pytest.raises(ValueError, match=r"started with other settings: beta=0.0 \(now 0.5\)$"):
        check_output(str(tmp_path), LACConfig.build("lac/PointHazard-v0", 0, {"beta": 0.5}, timesteps=1000),
                     resume=True)


def test_resume_may_raise_the_budget_only_where_the_lr_horizon_stays(tmp_path):
    """A run with its own lr horizon (the presets' 2.5M) is carried on to a larger budget; a run
    whose horizon is its budget is not, since a new budget would change its learning rates."""
    config = LACConfig.build("lac/PointHazard-v0", 0, {"lr_decay_horizon": 5000}, timesteps=1000)
    (tmp_path / CONFIG).write_text(json.dumps(run_config(config)))
    _fake_checkpoint(tmp_path, config)
    check_output(str(tmp_path), LACConfig.build("lac/PointHazard-v0", 0, {"lr_decay_horizon": 5000}, timesteps=4000),
                 resume=True)
    own = LACConfig.build("lac/PointHazard-v0", 0, {}, timesteps=1000)
    assert own.params()["lr_decay_horizon"] is None  # the tiny preset decays over the run's budget
    (tmp_path / CONFIG).write_text(json.dumps(run_config(own)))
    with pytest.raises(ValueError, match=r"total_env_steps=1000 \(now 4000\)"):
        check_output(str(tmp_path), LACConfig.build("lac/PointHazard-v0", 0, {}, timesteps=4000), resume=True)


def _fake_checkpoint(path, config):
    (path / "checkpoint").mkdir()
    (path / "checkpoint" / "rllib_checkpoint.json").write_text(json.dumps({
        "lac_rllib_version": lac_rllib.__version__, "checkpoint_format": CHECKPOINT_FORMAT, "task_id": config.task_id,
        "algo_config": config.params(), "cost_limit": 2.0, "episode_cost_discount": 1.0}, default=str))


def test_config_json_records_what_auto_resolved_to_and_resume_holds_it(tmp_path, monkeypatch):
    """langevin_dtype=auto is bfloat16 on a CPU with native bf16 and float32 elsewhere: config.json
    says which this run used, and a resume where it resolves otherwise is refused (other numerics);
    a run that recorded no resolution (before it was recorded) still resumes."""
    import lac_rllib.constrained.precision as precision

    monkeypatch.setattr(precision, "cpu_flags", lambda: {"avx2", "avx512_bf16"})
    config = LACConfig.build("lac/PointHazard-v0", 0, {"langevin_dtype": "auto"}, timesteps=1000)
    started = run_config(config)
    assert started["langevin_dtype"] == "auto" and started["resolved"] == {"langevin_dtype": "bfloat16"}
    (tmp_path / CONFIG).write_text(json.dumps(started))
    _fake_checkpoint(tmp_path, config)
    check_output(str(tmp_path), config, resume=True)  # same machine kind: resumes

    monkeypatch.setattr(precision, "cpu_flags", lambda: {"avx2"})
    elsewhere = LACConfig.build("lac/PointHazard-v0", 0, {"langevin_dtype": "auto"}, timesteps=1000)
    assert elsewhere.resolved() == {"langevin_dtype": "float32"}
    refused = r"resolved=\{'langevin_dtype': 'bfloat16'\} \(now \{'langevin_dtype': 'float32'\}\)"
    with pytest.raises(ValueError, match=refused):
        check_output(str(tmp_path), elsewhere, resume=True)

    (tmp_path / CONFIG).write_text(json.dumps({k: v for k, v in started.items() if k != "resolved"}))
    check_output(str(tmp_path), elsewhere, resume=True)


def test_algo_takes_a_users_module_by_its_import_path_and_refuses_a_bad_one_before_ray(tmp_path, monkeypatch,
                                                                                        capsys):
    """``--algo tests.algorithms.toy_algo``: its config, its own field by --set, its path in config.json."""
    from pathlib import Path

    import lac_rllib.train as cli

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))
    monkeypatch.setattr(cli, "start_ray", lambda **_: pytest.fail("Ray was started"))
    with pytest.raises(SystemExit) as e:
        cli.main(["--algo", "nowhere.algo", "--timesteps", "400", "--output", str(tmp_path / "bad")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"lac-train: error: --algo: unknown algo 'nowhere.algo'; accepted: {algos_text()}, "
                          "or the import path of your own algorithm's module"), err

    ran = {}

    def train(config, *args, **kwargs):  # what main hands the trainer, without training
        ran["config"] = config
        return {}

    monkeypatch.setattr(cli, "start_ray", lambda **_: None)
    monkeypatch.setattr(cli, "train", train)
    cli.main(["--algo", "tests.algorithms.toy_algo", "--set", "toy_marker=3.0", "--timesteps", "400",
              "--output", str(tmp_path / "toy")])
    config = ran["config"]
    assert type(config).__name__ == "ToyConfig" and config.toy_marker == 3.0
    assert run_config(config)["algo"] == "tests.algorithms.toy_algo"  # config.json names it by its path
