"""benchmarks/fidelity.py's report inputs: runs on disk, and earlier reports' curves whose run
directories a later session no longer has (``--include-curves``)."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fidelity():
    spec = importlib.util.spec_from_file_location("fidelity_benchmark", ROOT / "benchmarks" / "fidelity.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _write_run(out: Path, variant: str, seed: int, returns: list[float]) -> None:
    run = out / "runs" / variant / f"seed{seed}"
    run.mkdir(parents=True)
    lines = [json.dumps({"iteration": i + 1, "env_steps": 1000.0 * (i + 1), "episode_return": r, "episode_cost": 1.0,
                         "cost_limit": 25.0, "nu": 0.1, "time_s": 10.0 * (i + 1)}) for i, r in enumerate(returns)]
    (run / "progress.jsonl").write_text("\n".join(lines) + "\n")


def test_included_curves_add_the_runs_not_on_disk_and_disk_wins(fidelity, tmp_path):
    earlier = tmp_path / "earlier"
    _write_run(earlier, "ppo_lag", 0, [1.0, 2.0, 3.0])
    _write_run(earlier, "ppo_lag", 1, [-5.0, -5.0])  # rerun below: the new run must win
    fidelity.report(earlier, "lac/PointHazard-v0", ["ppo_lag"], None)
    now = tmp_path / "now"
    _write_run(now, "ppo_lag", 1, [7.0, 8.0, 9.0, 10.0])

    df = fidelity.load_curves(now, [earlier / "curves.csv"])
    runs = {seed: list(run["episode_return"]) for seed, run in df.groupby("seed")}
    assert runs == {0: [1.0, 2.0, 3.0], 1: [7.0, 8.0, 9.0, 10.0]}
    assert list(fidelity.load_curves(now)["seed"].unique()) == [1]  # nothing included unless asked

    (earlier / "table.md").write_text(  # what an earlier report listed: its commands survive with its curves
        "Commands:\n\n```\nlac-train --seed 0 --output /gone/runs/ppo_lag/seed0 --algo ppo_lag\n"
        "lac-train --seed 1 --output /gone/runs/ppo_lag/seed1 --algo ppo_lag\n```\n")
    (now / "runs" / "ppo_lag" / "seed1" / "command.txt").write_text("lac-train --output /now/runs/ppo_lag/seed1")
    text = fidelity.report(now, "lac/PointHazard-v0", ["ppo_lag"], None, include=[earlier / "curves.csv"])
    assert "their run directories gone: ppo_lag seed 0." in text
    commands = text.split("Commands:")[1]
    assert "/gone/runs/ppo_lag/seed0" in commands and "/now/runs/ppo_lag/seed1" in commands
    assert "/gone/runs/ppo_lag/seed1" not in commands  # the run on disk replaced it
    assert "Compared at 3,000 env steps" in text  # seed 0's 3k is the fewest reached


def test_a_file_that_is_not_a_curves_csv_is_refused(fidelity, tmp_path):
    bad = tmp_path / "other.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a curves.csv"):
        fidelity.load_curves(tmp_path, [bad])
