"""The plan's estimate calibrated on the machine that runs it (sweeps/estimate.py): a probe
measured slower or faster scales it, earlier trials in the same store win over the probe."""

import pytest
from mlflow.tracking import MlflowClient

from sweeps import estimate
from sweeps import run as cli


def _plan(tmp_path, monkeypatch, mode, *argv):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(estimate.ENV, mode)
    plan, = cli.make_plan(cli.parse_args(["--space", "ablation", "--storage", str(tmp_path / "rr"),
                                          "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", *argv]))
    return plan


@pytest.mark.parametrize("scale", [0.5, 2.0])
def test_a_probe_measured_slower_or_faster_scales_the_estimate(tmp_path, monkeypatch, scale):
    off = _plan(tmp_path, monkeypatch, "off")
    monkeypatch.setattr(estimate, "_probe_once", lambda: scale * estimate.PROBE_REFERENCE_S)
    probed = _plan(tmp_path, monkeypatch, "probe")
    assert probed.calibration[0] == pytest.approx(scale)
    assert probed.estimated_wall_s == pytest.approx(scale * off.estimated_wall_s)
    assert probed.estimated_cpu_h == pytest.approx(scale * off.estimated_cpu_h)
    assert "probe" in probed.calibration[1]
    assert off.calibration == (1.0, f"the rates as measured ({estimate.ENV}=off)")


def test_the_store_factor_is_the_median_of_measured_over_nominal():
    runs = [{"params": {"n": n}, "seconds": s} for n, s in ((10, 5.0), (10, 6.0), (20, 40.0), (10, 0.0))]
    factor, n = estimate.store_factor(runs, lambda p: float(p["n"]))
    assert (factor, n) == (pytest.approx(0.6), 3)  # median of 0.5, 0.6, 2.0; the unmeasured run left out
    assert estimate.store_factor(runs[:2], lambda p: float(p["n"])) is None  # fewer than MIN_TRIALS


def test_earlier_trials_in_the_store_win_over_the_probe(tmp_path, monkeypatch):
    off = _plan(tmp_path, monkeypatch, "off")
    trial = off.trials[0]  # three earlier runs of the plan's first trial, each 3x what the rates say
    nominal = estimate.nominal_trial_s({"task": trial.task, "timesteps": str(trial.timesteps), "torch_threads": "1",
                                   **{k: str(v) for k, v in trial.params.items()}})
    client = MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    exp = client.get_experiment_by_name(off.experiment) or client.get_experiment(
        client.create_experiment(off.experiment))
    parent = client.create_run(exp.experiment_id).info.run_id
    for _ in range(3):
        run = client.create_run(exp.experiment_id, tags={"mlflow.parentRunId": parent}).info.run_id
        for k, v in {"task": trial.task, "timesteps": trial.timesteps, "torch_threads": 1, **trial.params}.items():
            client.log_param(run, k, v)
        client.log_metric(run, "wall_time_s", 3.0 * nominal)
        start = client.get_run(run).info.start_time
        client.set_terminated(run, "FINISHED", end_time=start + int(3000 * nominal))  # the span: 3x the rates
    monkeypatch.setattr(estimate, "_probe_once", lambda: 10 * estimate.PROBE_REFERENCE_S)  # must not be used
    plan = _plan(tmp_path, monkeypatch, "auto")
    assert plan.calibration[0] == pytest.approx(3.0) and "3 earlier trials" in plan.calibration[1]
    assert plan.estimated_cpu_h == pytest.approx(3.0 * off.estimated_cpu_h)


def test_a_bad_calibration_setting_is_named(monkeypatch):
    monkeypatch.setenv(estimate.ENV, "fast")
    with pytest.raises(ValueError, match=r"LAC_SWEEP_CALIBRATION='fast'; accepted: auto \| store \| probe \| off"):
        estimate.mode()
