"""MLflow tracking of a sweep: one parent run per sweep, one child run per trial.

Everything goes through ``MlflowClient`` with an explicit tracking URI (trials run in other
processes and other working directories). Child runs are found again by their Tune trial id,
so a resumed sweep continues the same runs instead of duplicating them. A tracking server that
is away for a while (restart, network) costs no data: metrics and tags are buffered and sent
later, with a tag saying so; the other calls wait for it, up to ``RETRY_S`` seconds.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

# MLflow's own HTTP retries (7, exponential backoff: minutes per call) would stall a trial on
# every call while a server is down; fail fast there and retry here (RetryingClient, flush).
os.environ.setdefault("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "1")
os.environ.setdefault("MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR", "1")
os.environ.setdefault("MLFLOW_HTTP_REQUEST_TIMEOUT", "30")

from mlflow.entities import Metric, Param, RunTag  # noqa: E402
from mlflow.exceptions import MlflowException  # noqa: E402
from mlflow.tracking import MlflowClient  # noqa: E402

SWEEP_TAG, TRIAL_TAG, NODE_TAG = "lac.sweep", "lac.trial_id", "lac.node_id"
#: Tags "lac.resolved.<field>": what a rule-valued field ("auto") ran as on the trial's latest node.
RESOLVED_TAG_PREFIX = "lac.resolved."
CHECKPOINT_TAG = "lac.checkpoint_artifact_path"
LADDER_CONSTRAINT_TAG = "lac.ladder_constraint"  # a rung of a ladder along one of several constraints
ERROR_TAG = "lac.error"  # the last error of a failed attempt (cleared when a retry starts)
STATUS_TAG = "lac.sweep_status"  # on the parent run: finished | interrupted
STOPPED_TAG = "lac.stopped_early"  # on a child run the scheduler (ASHA) stopped before its budget
CONFIRMED_BY_TAG = "lac.confirmed_by"  # on a parent run: the name of the sweep that confirmed it
# A child run's params besides every LAC field (written by sweeps/trainable.py, read by the report).
P_TASK, P_SEED, P_GROUP, P_TIMESTEPS = "task", "seed", "group", "timesteps"
P_TASK_SOURCE = "task_source"  # what builds the task's env: a factory ("module:function") or a gymnasium id
P_ALGO, ALGO_TAG = "algo", "lac.algo"  # which algorithm the run trained (a registry name)
P_SWEPT_PARAM, P_SWEPT_VALUE = "swept_param", "swept_value"  # the grid point: which field, which value
CONFIG_ID_TAG = "lac.config_id"  # a child run's configuration without its seed (spaces.config_id)
CONFIG_TAG = "lac.config"  # the same, readable (algo-group-param=value-task, or algo-search-sample)
#: A trial's env fingerprint (lac_rllib/tasks/fingerprint.py): its id, and the whole as JSON.
ENV_FINGERPRINT_TAG, ENV_FINGERPRINT_JSON_TAG = "lac.env_fingerprint", "lac.env_fingerprint_json"
DEFAULT_TAG = "lac.default_config"  # "1" on runs of LAC's defaults: the report's baseline
PARENT_TAG = "mlflow.parentRunId"
NOTE_TAG = "mlflow.note.content"  # a run's description, rendered as markdown on its page
# MLflow 3's UI opens an experiment without this tag in GenAI mode (an empty "Traces" page);
# "custom_model_development" is its "Model training" kind, where runs, params and metrics show.
EXPERIMENT_KIND_TAG, MODEL_TRAINING_KIND = "mlflow.experimentKind", "custom_model_development"
DEFAULT_UI = "http://127.0.0.1:5000"  # where `mlflow ui` serves a local store
GAP_TAG, GAP_SECONDS_TAG = "lac.tracking_gap_retries", "lac.tracking_gap_s"
#: The words of the line a trial's log gets for each iteration whose metrics wait for the server.
BUFFERED = "buffered while the server is away:"
RETRY_S = float(os.environ.get("LAC_TRACKING_RETRY_S", "120"))  # how long a call waits for the server


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
        except Exception as e:  # any failure means unreachable
            raise ValueError(f"--tracking-uri {uri} is unreachable ({e}); "
                             "start `mlflow server` or fix the URI") from None
        return
    raise ValueError(f"--tracking-uri {uri!r}: accepted: sqlite:///ABSOLUTE/PATH.db or http(s)://HOST:PORT")


def experiment_id(client: MlflowClient, name: str, artifact_root: str | None) -> str:
    """The experiment's id, created (or tagged, if older) with the model-training kind."""
    exp = client.get_experiment_by_name(name)
    if exp is None:
        return client.create_experiment(name, artifact_location=artifact_root,
                                        tags={EXPERIMENT_KIND_TAG: MODEL_TRAINING_KIND})
    if EXPERIMENT_KIND_TAG not in exp.tags:  # a user's own choice of kind is left alone
        client.set_experiment_tag(exp.experiment_id, EXPERIMENT_KIND_TAG, MODEL_TRAINING_KIND)
    return exp.experiment_id


def ui_links(uri: str, experiment: str, run_id: str | None = None) -> dict[str, str]:
    """Direct links into the MLflow UI: the experiment's runs in "Model training" mode, and a run.

    A server's UI is at its tracking URI; a local store's at ``mlflow ui``'s default address.
    """
    base = uri.rstrip("/") if uri.startswith(("http://", "https://")) else DEFAULT_UI
    # Without the query the UI may open in its GenAI view, whatever the experiment's kind.
    mode = "?workflowType=machine_learning"
    links = {"runs": f"{base}/#/experiments/{experiment}/runs{mode}"}
    if run_id:
        links["run"] = f"{base}/#/experiments/{experiment}/runs/{run_id}{mode}"
    return links


def local_artifact_root(uri: str) -> str | None:
    # With a sqlite store, MLflow's default artifact root is "./mlruns" relative to each
    # process's cwd; trials run elsewhere, so pin it next to the database.
    if uri.startswith("sqlite:///"):
        return (Path(uri[len("sqlite:///"):]).parent / "mlruns").resolve().as_uri()
    return None


def learning_curve(client, run_id: str, cost_limit: float, constraints: tuple[str, ...] = ()):
    """A trial's learning curve from its run's metric histories, one row per logged iteration:
    env_steps (the step), episode_return, episode_cost, the trial's ``cost_limit``, and ν, ν's bound
    (where the algorithm logs one), the training's cost rate and, with several ``constraints``, each
    one's episode_cost/NAME and nu/NAME, by step (a DataFrame; what the
    trial's learning_curve.png, the sweep's learning_curves.png and the multiplier's behaviour,
    sweeps/reports/multiplier.py, are drawn from)."""
    import pandas as pd

    from lac_rllib.constrained.metrics import (
        COST_LIMIT,
        COST_RATE,
        ENV_STEPS,
        EPISODE_COST,
        EPISODE_RETURN,
        NU,
        NU_MAX,
        per_constraint,
    )

    returns = client.get_metric_history(run_id, EPISODE_RETURN)
    costs = client.get_metric_history(run_id, EPISODE_COST)
    curve = pd.DataFrame({ENV_STEPS: [m.step for m in returns], EPISODE_RETURN: [m.value for m in returns],
                          EPISODE_COST: [m.value for m in costs[:len(returns)]], COST_LIMIT: cost_limit})
    # Several constraints: each one's cost and multiplier (``constraints``: their names).
    own = [per_constraint(key, name) for name in constraints for key in (EPISODE_COST, NU)]
    for key in (NU, NU_MAX, COST_RATE, *own):
        by_step = {m.step: m.value for m in client.get_metric_history(run_id, key)}
        curve[key] = curve[ENV_STEPS].map(by_step).astype(float)
    return curve


def _params(d: dict) -> list[Param]:
    """MLflow params are strings (≤ 6000 chars); JSON keeps tuples and None readable."""
    return [Param(k, (v if isinstance(v, str) else json.dumps(v, default=str))[:6000]) for k, v in d.items()]


def param_value(text: str):
    """A logged param as its value: JSON for numbers and None, the text itself for a string
    (:func:`_params` logs strings as they are, e.g. a swept ``algo``)."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def _transient(e: Exception) -> bool:
    """A tracking server that is away or restarting (no connection, timeout, 5xx), not a bad request."""
    import requests

    if isinstance(e, (requests.ConnectionError, requests.Timeout, ConnectionError, TimeoutError)):
        return True
    if isinstance(e, requests.HTTPError):  # artifact uploads and downloads
        return e.response is not None and e.response.status_code >= 500
    if isinstance(e, MlflowException):  # rest_utils wraps every transport failure as "API request to ... failed"
        return str(e).startswith("API request to") or e.get_http_status_code() >= 500
    return False


class RetryingClient:
    """An ``MlflowClient`` whose calls wait out an unreachable server: retries with backoff
    (1, 2, 4, 8, 10, 10 ... s) for up to ``RETRY_S``, then the error is raised."""

    def __init__(self, client: MlflowClient, on_retry=None, on_recover=None):
        self._client = client
        self._on_retry, self._on_recover = on_retry or (lambda e: None), on_recover or (lambda: None)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        attr = getattr(self._client, name)
        if not callable(attr):
            return attr

        def call(*args, **kwargs):
            start, delay = time.monotonic(), 1.0
            while True:
                try:
                    result = attr(*args, **kwargs)
                except Exception as e:  # sorted by _transient
                    if not _transient(e) or time.monotonic() - start + delay > RETRY_S:
                        raise
                    self._on_retry(e)
                    time.sleep(delay)
                    delay = min(2 * delay, 10.0)
                    continue
                if delay > 1.0:
                    self._on_recover()
                return result

        return call


class TrialTracker:
    """The child run of one trial (used inside the Tune trial process).

    Metrics and tags are buffered: while the server is away they wait (training goes on) and
    go out with the next successful call, with a ``lac.tracking_gap_retries`` tag counting the
    failed attempts (``lac.tracking_gap_s``: seconds without the server). Everything else
    (setup, texts, artifacts, finish) waits for the server, up to ``RETRY_S``.
    """

    def __init__(self, uri: str, experiment: str, parent_run_id: str | None, trial_id: str, run_name: str):
        self.uri = uri
        self._raw = MlflowClient(uri)
        self.client = RetryingClient(self._raw, on_retry=self._gap, on_recover=self._recovered)
        self.parent_run_id, self.trial_id, self.run_name = parent_run_id, trial_id, run_name
        self.run_id: str | None = None
        self.previous = None  # the run as an earlier attempt left it (resume, retry)
        self._pending: list[Metric] = []
        self._tags: dict[str, str] = {}
        self._failures, self._reported, self._gap_s, self._down_since = 0, 0, 0.0, None
        self.experiment_id = experiment_id(self.client, experiment, local_artifact_root(uri))

    def _gap(self, error: Exception) -> None:
        self._failures += 1
        if self._down_since is None:
            self._down_since = time.monotonic()
            print(f"[lac tracking] {self.uri} unreachable ({str(error)[:200]}); buffering and retrying",
                  file=sys.stderr, flush=True)

    def _recovered(self) -> None:
        if self._down_since is not None:
            self._gap_s += time.monotonic() - self._down_since
            self._down_since = None
            print(f"[lac tracking] {self.uri} reachable again after {self._failures} failed attempts",
                  file=sys.stderr, flush=True)

    def open(self, params: dict, tags: dict) -> str:
        """Find this trial's run (resume, retry) or create it; log params and tags once.

        The run is looked up under this sweep's parent run only: trial ids have ~20 random bits
        and every sweep shares one experiment, so an id alone could adopt another sweep's run.
        """
        query = f"tags.`{TRIAL_TAG}` = '{self.trial_id}'"
        if self.parent_run_id:
            query += f" and tags.`{PARENT_TAG}` = '{self.parent_run_id}'"
        found = self.client.search_runs([self.experiment_id], filter_string=query, max_results=1)
        if found:
            self.run_id = found[0].info.run_id
            self.previous = found[0]  # what an earlier attempt left (status, tags, metrics)
            if found[0].info.status != "FINISHED":
                self.client.update_run(self.run_id, status="RUNNING")
                if ERROR_TAG in found[0].data.tags:  # a retry starts clean; error.txt keeps the history
                    self.client.delete_tag(self.run_id, ERROR_TAG)
            return self.run_id
        all_tags = {TRIAL_TAG: self.trial_id, "mlflow.runName": self.run_name, **tags}
        if self.parent_run_id:
            all_tags[PARENT_TAG] = self.parent_run_id
        run = self.client.create_run(self.experiment_id, run_name=self.run_name, tags=all_tags)
        self.run_id = run.info.run_id
        self.client.log_batch(self.run_id, params=_params(params))
        return self.run_id

    def logged_up_to(self, key: str) -> int:
        """The largest step logged for ``key`` by earlier attempts of this trial (0 if none)."""
        if self.previous is None:
            return 0
        return max((m.step for m in self.client.get_metric_history(self.run_id, key)), default=0)

    def log_metrics(self, metrics: dict, step: int) -> None:
        now = int(time.time() * 1000)
        self._pending += [Metric(k, float(v), now, int(step)) for k, v in metrics.items()]
        if not self.flush():  # one line per iteration in the trial's log: training goes on meanwhile
            print(f"[lac tracking] {BUFFERED} step {step}: {len(self._pending)} metrics wait for {self.uri}",
                  file=sys.stderr, flush=True)

    def set_tags(self, tags: dict) -> None:
        self._tags.update({k: str(v) for k, v in tags.items()})
        self.flush()

    def flush(self, wait: bool = False) -> bool:
        """Send buffered metrics and tags. If the server is away, keep them for the next call and
        return False; with ``wait``, retry up to ``RETRY_S`` and then raise."""
        if self.run_id is None:
            return False
        client = self.client if wait else self._raw
        try:
            while True:
                if self._failures != self._reported:  # report the gap along with the data
                    gap = self._gap_s + (time.monotonic() - self._down_since if self._down_since is not None else 0)
                    self._tags.update({GAP_TAG: str(self._failures), GAP_SECONDS_TAG: f"{gap:.1f}"})
                    self._reported = self._failures
                if not (self._pending or self._tags):
                    break
                metrics, tags = self._pending[:900], list(self._tags.items())[:100]  # log_batch limits
                client.log_batch(self.run_id, metrics=metrics, tags=[RunTag(k, v) for k, v in tags])
                del self._pending[:len(metrics)]
                for k, v in tags:
                    if self._tags.get(k) == v:
                        del self._tags[k]
        except Exception as e:  # the store may be away; keep everything and retry
            if wait:
                raise
            self._gap(e)
            return False
        self._recovered()
        return True

    def log_artifacts(self, local_dir: str, artifact_path: str | None = None) -> None:
        self.flush(wait=True)  # the metrics first: the final artifacts are read back from them
        self.client.log_artifacts(self.run_id, local_dir, artifact_path)

    def log_text(self, text: str, name: str) -> None:
        self.client.log_text(self.run_id, text, name)

    def finish(self, status: str = "FINISHED") -> None:
        self.flush(wait=True)
        self.client.set_terminated(self.run_id, status=status)


class SweepTracker:
    """The parent run of a sweep (used in the driver)."""

    def __init__(self, uri: str, experiment: str):
        self.uri, self.experiment = uri, experiment
        self.client = RetryingClient(MlflowClient(uri))
        self.experiment_id = experiment_id(self.client, experiment, local_artifact_root(uri))

    def start(self, name: str, params: dict, tags: dict, run_id: str | None = None) -> str:
        if run_id:  # resume: the same parent run
            self.client.update_run(run_id, status="RUNNING")
            return run_id
        run = self.client.create_run(self.experiment_id, run_name=name, tags={SWEEP_TAG: "1", **tags})
        self.client.log_batch(run.info.run_id, params=_params(params))
        return run.info.run_id

    def links(self, run_id: str | None = None) -> dict[str, str]:
        return ui_links(self.uri, self.experiment_id, run_id)

    def set_note(self, run_id: str, markdown: str) -> None:
        """The run's description in the UI (MLflow's note)."""
        self.client.set_tag(run_id, NOTE_TAG, markdown)

    def children(self, parent_run_id: str) -> list:
        return self.client.search_runs(
            [self.experiment_id], filter_string=f"tags.`{PARENT_TAG}` = '{parent_run_id}'", max_results=10_000)
