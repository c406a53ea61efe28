"""benchmarks/fidelity.py's report inputs: runs on disk, and earlier reports' curves whose run
directories are gone (``--include-curves``); the commands it writes name no machine's paths."""

import json
import re
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.benchmarks.loader import load_benchmark

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fidelity():
    return load_benchmark("fidelity")


# An absolute path in a command: a word (or a --set value) that starts with "/" or a drive letter.
ABSOLUTE = re.compile(r"(?:^|[\s=])(?:/|[A-Za-z]:[\\/])\S*")


def _write_run(out: Path, variant: str, seed: int, returns: list[float]) -> None:
    run = out / "runs" / variant / f"seed{seed}"
    run.mkdir(parents=True, exist_ok=True)
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
    assert "From earlier reports' curves (RUN_DIR/earlier/curves.csv)" in text and str(tmp_path) not in text
    commands = text.split("Commands:")[1]
    # the old absolute paths, rewritten with the run root as the placeholder
    assert "--output RUN_DIR/gone/runs/ppo_lag/seed0" in commands
    assert "--output RUN_DIR/now/runs/ppo_lag/seed1" in commands
    assert "/gone/runs/ppo_lag/seed1" not in commands  # the run on disk replaced it
    assert not ABSOLUTE.findall(commands), commands
    assert "Compared at 3,000 env steps" in text  # seed 0's 3k is the fewest reached


def test_a_file_that_is_not_a_curves_csv_is_refused(fidelity, tmp_path):
    bad = tmp_path / "other.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a curves.csv"):
        fidelity.load_curves(tmp_path, [bad])


def test_written_commands_name_the_run_root_as_a_placeholder(fidelity, tmp_path, monkeypatch):
    """command.txt and the table's commands say RUN_DIR/<out name>/runs/<variant>/seed<k>; the run
    itself is started with the real directory."""
    started = []

    def popen(cmd, **kwargs):
        kwargs["stdout"].close()
        started.append(cmd)
        return SimpleNamespace(pid=0)

    monkeypatch.setattr(fidelity, "subprocess", SimpleNamespace(Popen=popen, STDOUT=subprocess.STDOUT))  # no run
    out = tmp_path / "fidelity-runs" / "pointhazard"
    fidelity.launch(out, "lac/PointHazard-v0", "ppo_lag", ["algo=ppo_lag", "lagrangian_lr=0.0"], 1, 2000)
    run = out / "runs" / "ppo_lag" / "seed1"
    assert started[0][started[0].index("--output") + 1] == str(run)  # the run gets the real path
    written = (run / "command.txt").read_text()
    assert written == ("lac-train --task lac/PointHazard-v0 --seed 1 --timesteps 2000 --output "
                       "RUN_DIR/pointhazard/runs/ppo_lag/seed1 --checkpoint-every 2 --algo ppo_lag "
                       "--set lagrangian_lr=0.0\n")
    assert not ABSOLUTE.findall(written) and str(tmp_path) not in written

    _write_run(out, "ppo_lag", 1, [1.0, 2.0])
    commands = fidelity.report(out, "lac/PointHazard-v0", ["ppo_lag"], 2000).split("Commands:")[1]
    assert "--output RUN_DIR/pointhazard/runs/ppo_lag/seed1" in commands
    assert not ABSOLUTE.findall(commands) and str(tmp_path) not in commands


@pytest.mark.parametrize("path, written", [
    ("/work/fidelity-runs/pointgoal1-campaign/runs/defaults/seed0", "RUN_DIR/pointgoal1-campaign/runs/defaults/seed0"),
    ("/root/x/runs/bf16/seed1", "RUN_DIR/x/runs/bf16/seed1"),
    ("RUN_DIR/pointgoal1/runs/new/seed0", "RUN_DIR/pointgoal1/runs/new/seed0"),  # already so
])
def test_portable_output(fidelity, path, written):
    assert fidelity.portable_output(path) == written
    assert fidelity.portable_command(f"lac-train --seed 0 --output {path} --checkpoint-every 2") == (
        f"lac-train --seed 0 --output {written} --checkpoint-every 2")


def test_the_table_shows_the_published_figures_of_the_algorithms_it_ran(fidelity):
    commands = [
        "lac-train --task SafetyPointGoal1-v0 --seed 0 --output RUN_DIR/x/runs/cpo/seed0 --algo cpo",
        "lac-train --task SafetyPointGoal1-v0 --seed 0 --output RUN_DIR/x/runs/trpo/seed0 --algo trpo_lag "
        "--set lagrangian_lr=0.0 --set nu_init=0.0",
        "lac-train --task SafetyPointGoal1-v0 --seed 0 --output RUN_DIR/x/runs/defaults/seed0",
    ]
    variants = fidelity.variant_algos(commands)
    assert variants == {"cpo": ("cpo", False), "trpo": ("trpo_lag", True), "defaults": ("lac", False)}
    rows = fidelity.published_rows("SafetyPointGoal1-v0", variants, shown=[])
    # CPO's figures from sweeps/reports/published.yaml (the paper's Table 2 and OmniSafe's), OmniSafe's
    # unconstrained TRPO beside the pinned run; nothing for LAC (its paper row is the table's own).
    assert rows == ["| paper CPO, 2.5M steps | | 23.16 ± 2.09 | 46.00 ± 15.85 | | | |",
                    "| OmniSafe CPO, 10M steps | | 20.46 ± 1.38 | 28.84 ± 7.76 | | | |",
                    "| unconstrained TRPO (OmniSafe), 10M steps | | 27.20 | 45.88 | | | |"]


def test_the_plot_leaves_out_a_panel_no_run_has_values_for(fidelity, tmp_path, monkeypatch):
    """A report of baselines only has no chain to plot: its figure has no empty 'at a bound' panel."""
    import matplotlib.pyplot as plt

    made = []
    subplots = plt.subplots
    monkeypatch.setattr(plt, "subplots", lambda rows, cols, **kw: made.append(cols) or subplots(rows, cols, **kw))
    _write_run(tmp_path / "baselines", "ppo_lag", 0, [1.0, 2.0])
    fidelity.report(tmp_path / "baselines", "lac/PointHazard-v0", ["ppo_lag"], None)
    run = tmp_path / "lac" / "runs" / "lac" / "seed0"
    _write_run(tmp_path / "lac", "lac", 0, [1.0, 2.0])
    lines = (run / "progress.jsonl").read_text().splitlines()
    rows = [{**json.loads(line), "langevin_at_bound": 0.1} for line in lines]
    (run / "progress.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    fidelity.report(tmp_path / "lac", "lac/PointHazard-v0", ["lac"], None)
    assert made == [3, 4]


PG = "SafetyPointGoal1-v0"
LAG_PG1 = "https://github.com/Gaiejj/omnisafe_benchmarks_cruve/blob/9e1f6126be173c35fe8ad8683c9b8a95d6c51373/off-policy/benchmarks/lag_pointgoal1_3e6.png"  # noqa: E501
FIRST_ORDER_PG1 = "https://github.com/Gaiejj/omnisafe_benchmarks_cruve/blob/9e1f6126be173c35fe8ad8683c9b8a95d6c51373/on-policy/benchmarks/first_order_pointgoal1_1e7.png"  # noqa: E501


def _curves(steps: int):
    """One PPO-L run, an iteration every 50k env steps up to ``steps``."""
    import pandas as pd

    n = steps // 50_000
    return pd.DataFrame({"variant": "ppo", "seed": 0, "iteration": range(1, n + 1),
                         "env_steps": [50_000.0 * (i + 1) for i in range(n)], "episode_return": 1.0,
                         "episode_cost": 2.0, "cost_limit": 25.0, "nu": 0.1, "langevin_at_bound": float("nan")})


def test_a_run_at_500k_is_set_beside_omnisafes_figure_at_500k_read_from_its_curve(fidelity):
    text, common = fidelity.final_table(_curves(500_000), PG, ["ppo"], variants={"ppo": ("ppo_lag", False)})
    assert common == 500_000
    # OmniSafe's PPO-L and SAC-Lag at 500k, read off its curves: labelled so, each with the reading's ±.
    assert "| OmniSafe PPO-L, 500k steps, read from a curve | | 16.2 (read ±1) | 59 (read ±2) | | | |" in text
    assert "| OmniSafe SAC-Lag, 500k steps, read from a curve | | 25.6 (read ±1) | 47 (read ±4) | | | |" in text
    assert "12.96" not in text and "21.45" not in text  # not their 1e7 / 3e6 tables
    assert (f"Read from a curve: the height of the source's mean curve at that budget in [lag_pointgoal1_3e6.png]"
            f"({LAG_PG1}), [first_order_pointgoal1_1e7.png]({FIRST_ORDER_PG1}) (sweeps/reports/published.yaml), ± the "
            "reading's tolerance, not a std over seeds.") in text
    assert text.count("| OmniSafe PPO-L,") == 1  # shown once though the variant runs it too
    # Nothing is read at 750k: the final figures, each with its budget, and no curve named.
    text, _ = fidelity.final_table(_curves(750_000), PG, ["ppo"], variants={"ppo": ("ppo_lag", False)})
    assert "| OmniSafe PPO-L, 10M steps | | 12.96 ± 6.95 | 25.80 ± 34.99 | | | |" in text
    assert "| OmniSafe SAC-Lag, 3M steps | | 21.45 ± 6.97 | 19.17 ± 9.72 | | | |" in text
    assert "read from a curve" not in text.lower()
    # The paper's figure has no reading at 750k either: its 2.5M, said.
    assert "| paper PPO-L, 2.5M steps | | 11.36 ± 4.23 | 16.48 ± 10.95 | | | |" in text
