"""MLflow tracking of a sweep: one parent run per sweep, one child run per trial.

Everything goes through ``MlflowClient`` with an explicit tracking URI (trials run in other
processes and other working directories). Child runs are found again by their Tune trial id,
so a resumed sweep continues the same runs instead of duplicating them. Metric logging buffers
and retries: a tracking server that is away for a while costs no data and leaves a tag saying so.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from mlflow.entities import Metric, Param, RunTag
from mlflow.tracking import MlflowClient

SWEEP_TAG, TRIAL_TAG, NODE_TAG = "lac.sweep", "lac.trial_id", "lac.node_id"
CHECKPOINT_TAG = "lac.checkpoint_artifact_path"
PARENT_TAG = "mlflow.parentRunId"


def default_tracking_uri(cwd: str | None = None) -> str:
    """A local store in the working directory (no server needed)."""
    return f"sqlite:///{Path(cwd or os.getcwd()).resolve() / 'mlflow.db'}"


def check_reachable(uri: str) -> None:
    """Raise ValueError with the URI and the reason if the tracking store cannot be used."""
    if uri.startswith("sqlite:///"):
        folder = Path(uri[len("sqlite:///"):]).parent
        if not folder.is_dir() or not os.access(folder, os.W_OK):
            raise ValueError(f"--tracking-uri {uri}: folder {folder} does not exist or is not writable")
        return
    if uri.startswith(("http://", "https://")):
        import urllib.request

        try:
            with urllib.request.urlopen(uri.rstrip("/") + "/health", timeout=5) as r:
                r.read()
        except Exception as e:  # noqa: BLE001 - any failure means unreachable
            raise ValueError(f"--tracking-uri {uri} is unreachable ({e}); start `mlflow server` or fix the URI") from None
        return
    raise ValueError(f"--tracking-uri {uri!r}: accepted: sqlite:///ABSOLUTE/PATH.db or http(s)://HOST:PORT")


def experiment_id(client: MlflowClient, name: str, artifact_root: str | None) -> str:
    exp = client.get_experiment_by_name(name)
    if exp is not None:
        return exp.experiment_id
    return client.create_experiment(name, artifact_location=artifact_root)


def local_artifact_root(uri: str) -> str | None:
    # With a sqlite store, MLflow's default artifact root is "./mlruns" relative to each
    # process's cwd; trials run elsewhere, so pin it next to the database.
    if uri.startswith("sqlite:///"):
        return (Path(uri[len("sqlite:///"):]).parent / "mlruns").resolve().as_uri()
    return None


def _params(d: dict) -> list[Param]:
    """MLflow params are strings (≤ 6000 chars); JSON keeps tuples and None readable."""
    return [Param(k, (v if isinstance(v, str) else json.dumps(v, default=str))[:6000]) for k, v in d.items()]


class TrialTracker:
    """The child run of one trial (used inside the Tune trial process)."""

    def __init__(self, uri: str, experiment: str, parent_run_id: str | None, trial_id: str, run_name: str):
        self.client = MlflowClient(uri)
        self.experiment_id = experiment_id(self.client, experiment, local_artifact_root(uri))
        self.parent_run_id, self.trial_id, self.run_name = parent_run_id, trial_id, run_name
        self.run_id: str | None = None
        self._pending: list[Metric] = []
        self._failures = 0

    def open(self, params: dict, tags: dict) -> str:
        """Find this trial's run (resume) or create it; log params and tags once."""
        found = self.client.search_runs(
            [self.experiment_id], filter_string=f"tags.`{TRIAL_TAG}` = '{self.trial_id}'", max_results=1)
        if found:
            self.run_id = found[0].info.run_id
            self.client.update_run(self.run_id, status="RUNNING")
            return self.run_id
        all_tags = {TRIAL_TAG: self.trial_id, "mlflow.runName": self.run_name, **tags}
        if self.parent_run_id:
            all_tags[PARENT_TAG] = self.parent_run_id
        run = self.client.create_run(self.experiment_id, run_name=self.run_name, tags=all_tags)
        self.run_id = run.info.run_id
        self.client.log_batch(self.run_id, params=_params(params))
        return self.run_id

    def log_metrics(self, metrics: dict, step: int) -> None:
        now = int(time.time() * 1000)
        self._pending += [Metric(k, float(v), now, int(step)) for k, v in metrics.items()]
        self.flush()

    def flush(self) -> bool:
        """Send buffered metrics; on failure keep them for the next call and count the gap."""
        try:
            for i in range(0, len(self._pending), 900):  # log_batch takes at most 1000 metrics
                self.client.log_batch(self.run_id, metrics=self._pending[i:i + 900])
        except Exception:  # noqa: BLE001 - the store may be away; keep everything and retry
            self._failures += 1
            return False
        self._pending = []
        if self._failures:
            self.client.set_tag(self.run_id, "lac.tracking_gap_retries", str(self._failures))
        return True

    def log_artifacts(self, local_dir: str, artifact_path: str | None = None) -> None:
        self.client.log_artifacts(self.run_id, local_dir, artifact_path)

    def log_text(self, text: str, name: str) -> None:
        self.client.log_text(self.run_id, text, name)

    def set_tags(self, tags: dict) -> None:
        self.client.log_batch(self.run_id, tags=[RunTag(k, str(v)) for k, v in tags.items()])

    def finish(self, status: str = "FINISHED") -> None:
        self.flush()
        self.client.set_terminated(self.run_id, status=status)


class SweepTracker:
    """The parent run of a sweep (used in the driver)."""

    def __init__(self, uri: str, experiment: str):
        self.uri, self.experiment = uri, experiment
        self.client = MlflowClient(uri)
        self.experiment_id = experiment_id(self.client, experiment, local_artifact_root(uri))

    def start(self, name: str, params: dict, tags: dict, run_id: str | None = None) -> str:
        if run_id:  # resume: the same parent run
            self.client.update_run(run_id, status="RUNNING")
            return run_id
        run = self.client.create_run(self.experiment_id, run_name=name, tags={SWEEP_TAG: "1", **tags})
        self.client.log_batch(run.info.run_id, params=_params(params))
        return run.info.run_id

    def children(self, parent_run_id: str) -> list:
        return self.client.search_runs(
            [self.experiment_id], filter_string=f"tags.`{PARENT_TAG}` = '{parent_run_id}'", max_results=10_000)
