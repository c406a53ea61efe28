"""sweeps/evaluate.py: the evaluation CLI, by path and against a local MLflow store."""

import json
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sweeps import evaluate as cli
from sweeps.integrity import CHECKSUM_TAG, manifest_tag
from sweeps.tracking import CHECKPOINT_TAG, SWEEP_TAG

# One worker runs this module: its module-scoped fixture is expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("evaluate_cli"), pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "sweeps" / "evaluate.py"
TASK = "lac/PointHazard-v0"




def run_main(capsys, *argv):
    """Run the CLI's main() in-process: (exit code, stdout, stderr)."""
    try:
        code = cli.main(list(argv))
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


# Runs the CLI as `python sweeps/evaluate.py ...` would, then reports whether Ray was initialised.
_WRAPPER = """
import runpy, sys
sys.argv = [sys.argv[1]] + sys.argv[2:]
code = 0
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
except SystemExit as e:
    code = e.code
import ray
print("RAY_INITIALIZED", ray.is_initialized(), file=sys.stderr)
sys.exit(code)
"""


def run_subprocess(*argv, timeout=300):
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_ADDRESS")}
    return subprocess.run([sys.executable, "-c", _WRAPPER, str(SCRIPT), *argv], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=str(REPO))


# ----------------------------------------------------------------------------- by path


def test_cli_by_path_in_a_fresh_process_without_ray(checkpoint):
    from lac_rllib.evaluation import evaluate, restore_policy

    proc = run_subprocess("--checkpoint", checkpoint, "--episodes", "2", "--seed", "5", "--json",
                          "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "RAY_INITIALIZED False" in proc.stderr
    assert "Started a local Ray instance" not in proc.stdout + proc.stderr
    lines = proc.stdout.strip().splitlines()
    result = json.loads(lines[-1])
    human = "\n".join(lines[:-1])
    for word in ("return", "cost limit", "within limit", "±"):
        assert word in human
    # Same numbers as in this process: restore + evaluation are deterministic across processes.
    here = evaluate(restore_policy(checkpoint), 2, seed=5, progress=False)
    assert result["returns"] == here["returns"] and result["costs"] == here["costs"]
    assert result["cost_limit"] == 2.0 and result["task"] == TASK and result["actions"] == "generator"


def test_cli_langevin_human_output(checkpoint, capsys):
    code, out, err = run_main(capsys, "--checkpoint", checkpoint, "--episodes", "1", "--actions",
                              "langevin", "--langevin-steps", "4", "--no-progress")
    assert code == 0, err
    assert "actions langevin" in out and "energy" in out and "T=4" in out
    assert not out.strip().splitlines()[-1].startswith("{")  # no --json, no JSON


# ----------------------------------------------------------------------------- errors (exit code 2)


def test_cli_missing_path_exit_code_in_subprocess(tmp_path):
    proc = run_subprocess("--checkpoint", str(tmp_path / "missing"))
    assert proc.returncode == 2
    assert "evaluate: error: checkpoint not found" in proc.stderr


@pytest.fixture
def ckpt_copy(checkpoint, tmp_path):
    dst = tmp_path / "checkpoint"
    shutil.copytree(checkpoint, dst)
    return dst


@pytest.mark.parametrize("damage, message", [
    ("version", "version mismatch: written by lac-rllib 9.9.0"),
    ("metadata", "metadata"),
    ("module", "cannot restore the RLModule"),
])
def test_cli_bad_checkpoints_exit_2(ckpt_copy, capsys, damage, message):
    meta_file = ckpt_copy / "rllib_checkpoint.json"
    if damage == "version":
        meta = json.loads(meta_file.read_text())
        meta["lac_rllib_version"] = "9.9.0"
        meta_file.write_text(json.dumps(meta))
    elif damage == "metadata":
        meta_file.write_bytes(b"\x00\x01garbage")
    else:
        (ckpt_copy / "learner_group/learner/rl_module/default_policy/module_state.pkl").write_bytes(b"xx")
    code, out, err = run_main(capsys, "--checkpoint", str(ckpt_copy), "--no-progress")
    assert code == 2
    lines = err.strip().splitlines()
    assert lines[-1].startswith("evaluate: error: ") and message in lines[-1]
    assert "corrupt checkpoint" in lines[-1] or damage == "version"


def test_cli_bad_arguments_exit_2(checkpoint, capsys):
    code, _, err = run_main(capsys, "--checkpoint", checkpoint, "--episodes", "0")
    assert code == 2 and "--episodes 0 is invalid" in err
    code, _, err = run_main(capsys, "--checkpoint", checkpoint, "--langevin-steps", "5")
    assert code == 2 and "need a chain mode (--actions langevin)" in err
    code, _, err = run_main(capsys, "--episodes", "1")
    assert code == 2 and "one of the arguments" in err


@pytest.fixture(scope="module")
def ppo_lag_checkpoint(tmp_path_factory, ray_session):
    """A PPO-Lag checkpoint after one tiny iteration."""
    from lac_rllib.algorithms.registry import build_config

    algo = build_config("ppo_lag", TASK, 0, {"train_batch_size_per_learner": 400, "minibatch_size": 100,
                                             "num_epochs": 1, "num_envs_per_env_runner": 1},
                        timesteps=1000).build_algo()
    try:
        algo.train()
        return algo.save_to_path(str(tmp_path_factory.mktemp("ppo_lag") / "ckpt"))
    finally:
        algo.stop()


def test_cli_takes_the_modes_the_algorithm_declares(ppo_lag_checkpoint, capsys):
    """PPO-Lag declares generator and stochastic (its config's ACTIONS): a draw from π evaluates, and
    repeats at the same seed; LAC's chain is refused in one line naming the accepted modes."""
    runs = [run_main(capsys, "--checkpoint", ppo_lag_checkpoint, "--actions", "stochastic", "--episodes", "2",
                     "--json", "--no-progress") for _ in range(2)]
    (code, out, _), (_, again, _) = runs
    result = json.loads(out.strip().splitlines()[-1])
    assert code == 0 and result["actions"] == "stochastic" and result["episodes"] == 2
    assert result["algo"] == "ppo_lag" and json.loads(again.strip().splitlines()[-1]) == result
    code, _, err = run_main(capsys, "--checkpoint", ppo_lag_checkpoint, "--actions", "langevin", "--no-progress")
    line = err.strip().splitlines()[-1]
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--actions langevin is not a mode of ppo_lag" in line
    assert "accepted: --actions generator | stochastic" in line


# ----------------------------------------------------------------------------- MLflow


@pytest.fixture(scope="module")
def mlflow_store(checkpoint, tmp_path_factory):
    """A local MLflow store with one sweep: trials a (feasible, return 1), b (feasible,
    return 2), c (infeasible, return 5), d (no checkpoint); and a sweep with no feasible trial."""
    from mlflow.tracking import MlflowClient

    root = tmp_path_factory.mktemp("mlflow")
    uri = f"sqlite:///{root}/mlflow.db"
    client = MlflowClient(tracking_uri=uri)
    exp = client.create_experiment("lac-sweep", artifact_location=(root / "artifacts").as_uri())

    def trial(parent, name, ret, feasible, with_checkpoint=True, score=None):
        tags = {"mlflow.parentRunId": parent, "mlflow.runName": name}
        if with_checkpoint:
            tags[CHECKPOINT_TAG] = "checkpoint"
            tags[CHECKSUM_TAG] = manifest_tag(checkpoint)  # as the sweep's trials record it
        run = client.create_run(exp, tags=tags)
        rid = run.info.run_id
        client.log_param(rid, "task", TASK)
        for key, value in {"episode_return": ret, "episode_cost": 1.0 if feasible else 9.0,
                           "cost_limit": 2.0, "feasible": float(feasible), **(score or {})}.items():
            client.log_metric(rid, key, value)
        if with_checkpoint:
            client.log_artifacts(rid, checkpoint, artifact_path="checkpoint")
        client.set_terminated(rid)
        return rid

    sweep = client.create_run(exp, tags={SWEEP_TAG: "1"}).info.run_id
    runs = {"a": trial(sweep, "a", 1.0, True), "b": trial(sweep, "b", 2.0, True),
            "tampered": trial(sweep, "tampered", 0.5, True), "unverified": trial(sweep, "unverified", 0.4, True),
            "c": trial(sweep, "c", 5.0, False, with_checkpoint=False),
            # Its last iteration infeasible, its score (what the sweep ranked it on) feasible, but
            # below b's; and one whose score is infeasible though its last iteration looked best.
            "e": trial(sweep, "e", 0.1, False, with_checkpoint=False, score={"score_return": 1.5, "score_cost": 1.0}),
            "f": trial(sweep, "f", 9.0, True, with_checkpoint=False, score={"score_return": 9.0, "score_cost": 3.0}),
            "d": trial(sweep, "d", 0.0, True, with_checkpoint=False)}
    infeasible_sweep = client.create_run(exp, tags={SWEEP_TAG: "1"}).info.run_id
    trial(infeasible_sweep, "x", 3.0, False, with_checkpoint=False)
    client.delete_tag(runs["unverified"], CHECKSUM_TAG)  # logged before manifests existed
    # Someone with write access to the artifact store swaps a pickle for one that runs code.
    art = Path(client.get_run(runs["tampered"]).info.artifact_uri.removeprefix("file://")) / "checkpoint"
    target = art / "learner_group" / "learner" / "rl_module" / "default_policy" / "module_state.pkl"
    marker = root / "pwned"
    target.write_bytes(pickle.dumps(_Payload(str(marker))))
    return {"uri": uri, "client": client, "sweep": sweep, "infeasible_sweep": infeasible_sweep,
            "marker": marker, **runs}


class _Payload:
    """Unpickling this creates a file: a stand-in for arbitrary code in a crafted checkpoint."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def test_cli_run_id_logs_eval_metrics_back(mlflow_store, capsys):
    s = mlflow_store
    code, out, err = run_main(capsys, "--run-id", s["a"], "--tracking-uri", s["uri"], "--episodes", "2",
                              "--seed", "1", "--json", "--no-progress")
    assert code == 0, err
    result = json.loads(out.strip().splitlines()[-1])
    assert result["run_id"] == s["a"] and result["checkpoint"] == f"runs:/{s['a']}/checkpoint"
    metrics = s["client"].get_run(s["a"]).data.metrics
    assert metrics["eval/generator/return_mean"] == pytest.approx(result["return_mean"])
    assert metrics["eval/generator/cost_mean"] == pytest.approx(result["cost_mean"])
    assert metrics["eval/generator/within_limit_fraction"] == pytest.approx(result["within_limit_fraction"])
    assert metrics["episode_return"] == 1.0  # the trial's own metrics are untouched
    tags = s["client"].get_run(s["a"]).data.tags
    assert tags["lac.eval.generator.episodes"] == "2" and tags["lac.eval.generator.seed"] == "1"


def test_cli_best_of_picks_best_feasible_trial(mlflow_store):
    s = mlflow_store
    proc = run_subprocess("--best-of", s["sweep"], "--tracking-uri", s["uri"], "--episodes", "1",
                          "--actions", "langevin", "--json", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    # c has a higher return but is infeasible; f's last iteration is feasible, its score is not.
    assert result["run_id"] == s["b"]
    assert "best feasible trial of sweep" in proc.stdout
    metrics = s["client"].get_run(s["b"]).data.metrics
    assert metrics["eval/langevin/return_mean"] == pytest.approx(result["return_mean"])
    assert "eval/langevin/energy_refined_mean" in metrics
    assert "RAY_INITIALIZED False" in proc.stderr


@pytest.mark.parametrize("which, args, message", [
    ("d", "--run-id", "has no checkpoint (tag lac.checkpoint_artifact_path is not set)"),
    ("infeasible_sweep", "--best-of", "has no feasible trial"),
    ("a", "--best-of", "is not a sweep"),
    (None, "--run-id", "not found"),
])
def test_cli_mlflow_errors_exit_2(mlflow_store, capsys, which, args, message):
    s = mlflow_store
    run_id = s[which] if which else "0" * 32
    code, _, err = run_main(capsys, args, run_id, "--tracking-uri", s["uri"], "--no-progress")
    assert code == 2
    assert err.strip().splitlines()[-1].startswith("evaluate: error: ") and message in err


@pytest.mark.parametrize("which, message", [
    ("tampered", "checkpoint file learner_group/learner/rl_module/default_policy/module_state.pkl does not match "
                 "its recorded SHA-256"),
    ("unverified", "no SHA-256 manifest recorded"),
])
def test_cli_refuses_unverified_checkpoints_before_unpickling(mlflow_store, capsys, which, message):
    s = mlflow_store
    code, _, err = run_main(capsys, "--run-id", s[which], "--tracking-uri", s["uri"], "--no-progress")
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not s["marker"].exists(), "the crafted pickle was loaded"


def test_cli_mlflow_checkpoint_tag_without_artifact_exit_2(mlflow_store, capsys):
    s = mlflow_store
    s["client"].set_tag(s["d"], CHECKPOINT_TAG, "no/such/dir")
    try:
        code, _, err = run_main(capsys, "--run-id", s["d"], "--tracking-uri", s["uri"])
    finally:
        s["client"].delete_tag(s["d"], CHECKPOINT_TAG)
    assert code == 2 and "has no checkpoint" in err


def test_cli_unusable_tracking_uri_exit_2(tmp_path, capsys):
    uri = f"sqlite:///{tmp_path / 'no' / 'such' / 'mlflow.db'}"
    code, _, err = run_main(capsys, "--run-id", "0" * 32, "--tracking-uri", uri)
    assert code == 2 and "does not exist or is not writable" in err
