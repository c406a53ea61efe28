"""sweeps/tracking.py: a trial's run is found under its own sweep, and a retry starts clean."""

from mlflow.tracking import MlflowClient

from sweeps.tracking import ERROR_TAG, TRIAL_TAG, TrialTracker


def _parent(client, exp_id, name):
    return client.create_run(exp_id, run_name=name, tags={"lac.sweep": "1"}).info.run_id


def test_trial_runs_are_found_under_their_own_sweep_and_retries_drop_the_stale_error(tmp_path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    first = TrialTracker(uri, "exp", None, "t-0001", "x")  # creates the experiment
    client = MlflowClient(uri)
    sweep_a, sweep_b = _parent(client, first.experiment_id, "a"), _parent(client, first.experiment_id, "b")

    old = TrialTracker(uri, "exp", sweep_a, "abcde_00000", "label")
    old_run = old.open({"seed": 0}, {})
    old.finish("FINISHED")
    # Same trial id (Tune's ids have ~20 random bits), another sweep: a new run, not the old FINISHED one.
    new = TrialTracker(uri, "exp", sweep_b, "abcde_00000", "label")
    new_run = new.open({"seed": 0}, {})
    assert new_run != old_run and new.previous is None
    assert client.get_run(new_run).data.tags[TRIAL_TAG] == "abcde_00000"

    # A failed attempt leaves lac.error; the retry (same sweep, same trial) continues the run without it.
    new.set_tags({ERROR_TAG: "RuntimeError: boom"})
    new.flush()
    new.finish("FAILED")
    retry = TrialTracker(uri, "exp", sweep_b, "abcde_00000", "label")
    assert retry.open({"seed": 0}, {}) == new_run
    run = client.get_run(new_run)
    assert run.info.status == "RUNNING" and ERROR_TAG not in run.data.tags


def test_the_learning_curve_carries_nu_its_bound_and_the_cost_rate_by_step():
    """What the multiplier's behaviour is read from (sweeps/reports/multiplier.py): ν and the cost
    rate by env step, ν's bound NaN for an algorithm that logs none."""
    from types import SimpleNamespace

    from sweeps.tracking import learning_curve

    history = {"episode_return": [(1000, 1.0), (2000, 2.0)], "episode_cost": [(1000, 9.0), (2000, 4.0)],
               "nu": [(1000, 0.0), (2000, 0.5)], "cost_rate": [(1000, 0.009), (2000, 0.0065)]}
    client = SimpleNamespace(get_metric_history=lambda run, key: [SimpleNamespace(step=s, value=v)
                                                                   for s, v in history.get(key, [])])
    curve = learning_curve(client, "run", 5.0)
    assert curve["nu"].tolist() == [0.0, 0.5] and curve["cost_rate"].tolist() == [0.009, 0.0065]
    assert curve["nu_max"].isna().all() and curve["cost_limit"].tolist() == [5.0, 5.0]


def test_metrics_wait_while_the_server_is_away_and_arrive_with_the_gap_tagged(tmp_path, capsys, monkeypatch):
    """Each iteration logged during an outage says so in the trial's log (one line, with its step)
    and is delivered, stamped when it was logged, with the next call that reaches the server."""
    from sweeps.tracking import BUFFERED, GAP_TAG

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    tracker = TrialTracker(uri, "exp", None, "t-0001", "x")
    run_id = tracker.open({"seed": 0}, {})
    real = tracker._raw.log_batch
    monkeypatch.setattr(tracker._raw, "log_batch", lambda *a, **k: (_ for _ in ()).throw(ConnectionError("away")))
    tracker.log_metrics({"env_steps": 500.0}, step=500)
    tracker.log_metrics({"env_steps": 1000.0}, step=1000)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if BUFFERED in ln]
    assert [ln.split(BUFFERED)[1].split(":")[0].strip() for ln in lines] == ["step 500", "step 1000"], lines
    monkeypatch.setattr(tracker._raw, "log_batch", real)
    tracker.log_metrics({"env_steps": 1500.0}, step=1500)
    assert BUFFERED not in capsys.readouterr().err
    client = MlflowClient(uri)
    assert [m.step for m in client.get_metric_history(run_id, "env_steps")] == [500, 1000, 1500]
    assert client.get_run(run_id).data.tags[GAP_TAG] == "2"
