"""The sweep service on a real 2-node Ray cluster with a real MLflow tracking server, the path of
docker/README.md: healthy, a worker node lost mid-sweep, the server away for a while.

The cluster (head + 1 worker, 1 CPU each, reached at 127.0.0.1) and `mlflow server` (on
127.0.0.1) are started by ``docker/cluster.sh`` once for the module and always stopped; only what the script started is
stopped (never ``ray stop``: other Ray sessions may be running on this machine). A test that
breaks part of the set-up brings that part back first. Each sweep is the user's command,
``python sweeps/run.py --address ... --tracking-uri http://...``, run as a subprocess and checked
only through MLflow's REST API.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import requests

# One worker runs this module: its module-scoped fixture is expensive (pytest-xdist, --dist loadgroup).
pytestmark = [pytest.mark.xdist_group("cluster"), pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "docker" / "cluster.sh"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """docker/cluster.sh, driven from a test."""

    def __init__(self, root: Path):
        self.root = root
        self.env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
        # Ray's token authentication on, as in production, with a token of this test's own (not
        # ~/.ray/auth_token): the nodes, the driver and every worker get it from the environment.
        self.env.update({"LAC_CLUSTER_DIR": str(root), "RAY_AUTH_MODE": "token",
                         "RAY_AUTH_TOKEN": secrets.token_hex(32), "WORKERS": "1",
                         "CPUS_PER_NODE": "1", "OBJECT_STORE_MB": "256", "RAY_PORT": str(free_port()),
                         "MLFLOW_PORT": str(free_port()), "DASHBOARD_PORT": "", "RAY_DEDUP_LOGS": "0"})

    def sh(self, *args: str, timeout: float = 300) -> str:
        proc = subprocess.run(["bash", str(SCRIPT), *args], env=self.env, capture_output=True, text=True,
                              timeout=timeout)
        assert proc.returncode == 0, f"cluster.sh {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}"
        return proc.stdout

    @property
    def info(self) -> dict:
        """cluster.env: addresses, storage and the node ids of the running set-up."""
        lines = (self.root / "cluster.env").read_text().splitlines()
        return dict(line.split("=", 1) for line in lines if "=" in line)

    @property
    def uri(self) -> str:
        return self.info["LAC_TRACKING_URI"]

    def node_ids(self) -> tuple[str, str]:
        info = self.info
        return info["LAC_HEAD_NODE_ID"], info["LAC_WORKER_NODE_IDS"]

    def buffered_lines(self) -> int:
        """Lines in the nodes' worker logs saying an iteration's metrics wait for the server."""
        from sweeps.tracking import BUFFERED

        logs = self.root.glob("ray/*/session_latest/logs/worker-*.err")
        return sum(p.read_text(errors="replace").count(BUFFERED) for p in logs)

    def ensure_worker(self) -> None:
        """Bring worker-1 back if an earlier test killed it."""
        if not (self.root / "pids" / "worker-1").exists():
            self.sh("start", "worker-1")

    def sweep(self, name: str, *extra: str, cwd: Path) -> subprocess.Popen:
        """``python sweeps/run.py`` against this cluster and server (output in cwd/sweep.log)."""
        info = self.info
        cmd = [sys.executable, str(REPO / "sweeps" / "run.py"), "--space", "smoke", "--budget", "smoke",
               "--address", info["LAC_RAY_ADDRESS"], "--tracking-uri", info["LAC_TRACKING_URI"],
               "--storage", info["LAC_STORAGE"], "--name", name, "--experiment", name, "--max-concurrent", "2",
               *extra]
        with open(cwd / "sweep.log", "w") as log:
            proc = subprocess.Popen(cmd, cwd=cwd, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True)
        proc.log_path = cwd / "sweep.log"
        return proc


def wait_sweep(proc: subprocess.Popen, timeout: float) -> str:
    """Wait for a sweep subprocess (SIGKILL its process group on timeout); its output."""
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return Path(proc.log_path).read_text()


@pytest.fixture(scope="module")
def cluster():
    # A short root: Ray's unix socket paths live under it (limit ~107 characters).
    root = Path(tempfile.mkdtemp(prefix="lac-cl-", dir="/tmp"))
    c = Cluster(root)
    try:
        c.sh("start")
        yield c
    finally:
        c.sh("stop")
        if not os.environ.get("LAC_KEEP_CLUSTER_DIR"):  # =1 keeps logs, stores and Tune results
            shutil.rmtree(root, ignore_errors=True)


class MLflowREST:
    """The few MLflow REST calls the tests need (no MLflow client: what any HTTP user sees)."""

    def __init__(self, uri: str):
        self.uri = uri.rstrip("/")

    def get(self, endpoint: str, **params):
        r = requests.get(f"{self.uri}/api/2.0/{endpoint}", params=params, timeout=30)
        r.raise_for_status()
        return r.json()

    def experiment_id(self, name: str) -> str | None:
        r = requests.get(f"{self.uri}/api/2.0/mlflow/experiments/get-by-name",
                         params={"experiment_name": name}, timeout=30)
        return r.json()["experiment"]["experiment_id"] if r.ok else None

    def runs(self, experiment: str) -> list[dict]:
        """Every run of the experiment as {id, status, tags, params, metrics, artifact_uri}."""
        exp = self.experiment_id(experiment)
        if exp is None:
            return []
        r = requests.post(f"{self.uri}/api/2.0/mlflow/runs/search", timeout=30,
                          json={"experiment_ids": [exp], "max_results": 1000})
        r.raise_for_status()
        out = []
        for run in r.json().get("runs", []):
            data = run.get("data", {})
            out.append({"id": run["info"]["run_id"], "status": run["info"]["status"],
                        "artifact_uri": run["info"]["artifact_uri"],
                        "tags": {t["key"]: t["value"] for t in data.get("tags", [])},
                        "params": {p["key"]: p["value"] for p in data.get("params", [])},
                        "metrics": {m["key"]: m["value"] for m in data.get("metrics", [])}})
        return out

    def trials(self, experiment: str) -> list[dict]:
        return [r for r in self.runs(experiment) if "mlflow.parentRunId" in r["tags"]]

    def history(self, run_id: str, key: str) -> list[dict]:
        """[{step, value, timestamp}] of one metric, in step order."""
        ms = self.get("mlflow/metrics/get-history", run_id=run_id, metric_key=key, max_results=25000)
        return sorted(ms.get("metrics", []), key=lambda m: (m["step"], m["timestamp"]))

    def artifacts(self, run_id: str, path: str) -> list[dict]:
        """Every file under path (recursive) as {path, file_size}."""
        files = []
        for f in self.get("mlflow/artifacts/list", run_id=run_id, path=path).get("files", []):
            files += self.artifacts(run_id, f["path"]) if f["is_dir"] else [f]
        return files

    def download(self, artifact_uri: str, path: str) -> bytes:
        """A file through the server's artifact proxy (mlflow-artifacts:/...), as a worker would."""
        assert artifact_uri.startswith("mlflow-artifacts:/"), artifact_uri
        root = artifact_uri[len("mlflow-artifacts:"):].lstrip("/")
        r = requests.get(f"{self.uri}/api/2.0/mlflow-artifacts/artifacts/{root}/{path}", timeout=60)
        r.raise_for_status()
        return r.content


@pytest.fixture
def rest(cluster):
    return MLflowREST(cluster.uri)


def wait_until(predicate, timeout: float, what: str, poll: float = 0.5, proc: subprocess.Popen | None = None):
    """Poll predicate() until it returns something truthy; fail if the sweep exits first."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = predicate()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the sweep exited (rc={proc.returncode}) before: {what}")
        time.sleep(poll)
    pytest.fail(f"timed out after {timeout:.0f}s waiting for: {what}")


STEPS = [500, 1000, 1500, 2000]  # env_steps of the smoke budget's four iterations
SWEEP_TIMEOUT = 900
AWAY_STEPS = list(range(1000, 8001, 1000))  # the server-away test's 8 iterations (1,000 env steps each)


@pytest.fixture
def start_sweep(cluster, tmp_path):
    """Starts sweeps against the cluster; kills any still running at teardown."""
    procs = []

    def start(name, *extra):
        procs.append(cluster.sweep(name, *extra, cwd=tmp_path))
        return procs[-1]

    yield start
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def assert_finished_sweep(rest, name, n_trials, out):
    runs = rest.runs(name)
    parents = [r for r in runs if r["tags"].get("lac.sweep") == "1"]
    trials = [r for r in runs if "mlflow.parentRunId" in r["tags"]]
    assert len(parents) == 1 and parents[0]["status"] == "FINISHED", out[-3000:]
    assert parents[0]["tags"].get("lac.failed_trials") == "0"
    ids = [t["tags"]["lac.trial_id"] for t in trials]
    assert len(trials) == n_trials and len(set(ids)) == n_trials, f"one MLflow run per trial: {ids}"
    for t in trials:
        assert t["status"] == "FINISHED", (t["tags"].get("lac.error"), out[-3000:])
        assert t["tags"]["mlflow.parentRunId"] == parents[0]["id"]
    return trials


def assert_opens_on_the_results(rest, name, uri, out):
    """The MLflow UI opens on the results: model-training experiment, links printed, note on the parent."""
    exp = rest.experiment_id(name)
    tags = {t["key"]: t["value"] for t in rest.get("mlflow/experiments/get", experiment_id=exp)["experiment"]["tags"]}
    assert tags.get("mlflow.experimentKind") == "custom_model_development", tags
    parent = next(r for r in rest.runs(name) if r["tags"].get("lac.sweep") == "1")
    runs_link = f"{uri.rstrip('/')}/#/experiments/{exp}/runs?workflowType=machine_learning"
    run_link = f"{uri.rstrip('/')}/#/experiments/{exp}/runs/{parent['id']}?workflowType=machine_learning"
    assert out.count(runs_link) == 2 and out.count(run_link) == 2, out[-3000:]  # at start and at the end
    note = parent["tags"]["mlflow.note.content"]
    assert note.startswith(f"**Sweep `{name}`**: 4 of 4 trials finished"), note
    assert "**Best feasible configuration:**" in note
    for what in ("5", "10 (default)"):  # one row per swept value, with its seed count
        assert f"| smoke | langevin_steps={what} | 2 |" in note, note
    labels = sorted(t["tags"]["mlflow.runName"] for t in rest.trials(name))
    assert labels == [f"lac-smoke-langevin_steps={v}-PointHazard-v0-s{s}" for v in (10, 5) for s in (0, 1)], labels


def test_sweep_on_two_nodes_with_a_tracking_server(cluster, rest, start_sweep):
    cluster.ensure_worker()
    head, worker = cluster.node_ids()
    proc = start_sweep("healthy", "--seeds", "2")
    out = wait_sweep(proc, SWEEP_TIMEOUT)
    assert proc.returncode == 0, out[-3000:]

    trials = assert_finished_sweep(rest, "healthy", 4, out)
    assert_opens_on_the_results(rest, "healthy", cluster.uri, out)
    for t in trials:
        assert [m["step"] for m in rest.history(t["id"], "env_steps")] == STEPS
        for key in ("episode_return", "episode_cost", "nu", "critic_loss", "objective"):
            assert len(rest.history(t["id"], key)) == 4, key
    assert {t["tags"]["lac.node_id"] for t in trials} == {head, worker}, "trials ran on both nodes"

    # The final checkpoint of every trial comes back from the server, file by file.
    for t in trials:
        assert t["tags"]["lac.checkpoint_artifact_path"] == "checkpoint"
        files = rest.artifacts(t["id"], "checkpoint")
        assert "checkpoint/rllib_checkpoint.json" in {f["path"] for f in files}
        for f in files:
            assert len(rest.download(t["artifact_uri"], f["path"])) == int(f["file_size"]), f["path"]
        meta = json.loads(rest.download(t["artifact_uri"], "checkpoint/rllib_checkpoint.json"))
        assert meta["ray_version"] == "2.60.0" and "state_file" in meta, meta


def test_tracking_server_away_for_a_while(cluster, rest, start_sweep):
    """The MLflow server dies (SIGKILL) once trials log metrics and stays away ≥ 15 s, then is
    restarted on the same port and store: the trials train on meanwhile, their metrics arrive
    late but complete, the gap is tagged, and nothing logged before is lost."""
    cluster.ensure_worker()
    # 8 iterations, not the smoke budget's 4: a smoke trial can log its last iteration before the
    # kill takes hold, and then nothing trains during the outage (the next trials wait for the server).
    proc = start_sweep("server-away", "--seeds", "2", "--budget", str(AWAY_STEPS[-1]))

    def logging_trials():
        return [t for t in rest.trials("server-away") if "env_steps" in t["metrics"]]

    wait_until(logging_trials, 300, "a trial logging metrics", poll=0.2, proc=proc)
    before = {t["id"]: {**t, "history": rest.history(t["id"], "env_steps")} for t in rest.trials("server-away")}
    base = cluster.buffered_lines()  # earlier tests' outages, if any
    cluster.sh("kill", "mlflow")  # a crash: unreachable at once
    down = time.time()
    # Away ≥ 15 s and until two iterations were logged meanwhile (the trials' logs say so), well
    # within the 120 s a call waits: a fixed 15 s raced the trials on a loaded machine.
    points = [len(t["history"]) for t in before.values()]
    wait_until(lambda: time.time() - down >= 15 and cluster.buffered_lines() >= base + 2, 90,
               f"two iterations logged while the server was away (env-steps points per trial before: {points})",
               poll=0.5, proc=proc)
    up = time.time()  # unreachable for certain from `down` to `up`
    cluster.sh("start", "mlflow")

    out = wait_sweep(proc, SWEEP_TIMEOUT)
    assert proc.returncode == 0, out[-3000:]
    trials = assert_finished_sweep(rest, "server-away", 4, out)
    after = {t["id"]: t for t in trials}
    for t in trials:
        for key in ("env_steps", "episode_return", "episode_cost", "nu", "objective"):
            assert [m["step"] for m in rest.history(t["id"], key)] == AWAY_STEPS, (t["id"], key)

    # Nothing recorded before the outage is lost or changed.
    for run_id, old in before.items():
        assert old["params"].items() <= after[run_id]["params"].items()
        assert old["tags"].items() <= after[run_id]["tags"].items()
        assert all(m in rest.history(run_id, "env_steps") for m in old["history"])
        for key, value in old["metrics"].items():  # the latest value of every metric then
            assert value in [m["value"] for m in rest.history(run_id, key)], (run_id, key)

    # Training went on while the server was away (metrics stamped then, delivered later), and
    # the trials that could not deliver say so.
    while_down = {t["id"]: [m for m in rest.history(t["id"], "env_steps") if down * 1000 <= m["timestamp"] <= up * 1000]
                  for t in trials}
    assert any(while_down.values()), ("no metric was produced while the server was down", out[-3000:])
    for run_id, ms in while_down.items():
        if ms:
            assert int(after[run_id]["tags"].get("lac.tracking_gap_retries", "0")) >= 1, after[run_id]["tags"]
            assert float(after[run_id]["tags"]["lac.tracking_gap_s"]) > 0


def test_worker_node_lost_mid_sweep(cluster, rest, start_sweep):
    """The worker is SIGKILLed (raylet, its workers, the trial) while a trial runs on it: Tune
    retries that trial (FailureConfig) on the head, in the same MLflow run, and the sweep ends."""
    cluster.ensure_worker()
    head, worker = cluster.node_ids()
    proc = start_sweep("node-lost", "--seeds", "1", "--max-failures", "2")

    def running_on_worker():
        return [t for t in rest.trials("node-lost") if t["tags"].get("lac.node_id") == worker
                and t["status"] == "RUNNING"]

    victim = wait_until(running_on_worker, 300, "a trial running on the worker node", proc=proc)[0]
    cluster.sh("kill", "worker-1")
    out = wait_sweep(proc, SWEEP_TIMEOUT)
    assert proc.returncode == 0, out[-3000:]

    trials = assert_finished_sweep(rest, "node-lost", 2, out)
    retried = next(t for t in trials if t["id"] == victim["id"])
    assert retried["tags"]["lac.node_id"] == head, "the lost trial finished on the surviving node"
    for t in trials:
        steps = [m["step"] for m in rest.history(t["id"], "env_steps")]
        assert sorted(set(steps)) == STEPS, steps  # complete (iterations redone after a restore repeat)
