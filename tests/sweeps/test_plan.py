"""The plan a user sees before Ray starts is what the README promises (no Ray: make_plan only)."""

import re
from pathlib import Path

import pytest

from sweeps import run as cli

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()
FIRST_SCREEN = README.split("---")[0]


def _plan(tmp_path, monkeypatch, *argv):
    monkeypatch.chdir(tmp_path)  # the default MLflow store goes to the working directory
    return cli.make_plan(cli.parse_args(["--storage", str(tmp_path / "ray_results"), *argv]))


def test_the_default_ablation_is_what_the_readme_says(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "ablation")
    assert (plan.task, plan.budget, plan.timesteps, plan.n_trials) == ("lac/PointHazard-v0", "quick", 40_000, 21)
    labels = {t.config_label() for t in plan.trials}
    assert labels == {f"NI-langevin_steps={t}-PointHazard-v0" for t in (20, 30)} | {
        f"VT-langevin_steps={t}-PointHazard-v0" for t in (10, 20, 30)} | {
        f"PR-beta={b}-PointHazard-v0" for b in (0.5, 1.0)}
    defaults = [t.label() for t in plan.trials if t.default]
    assert defaults == [f"VT-langevin_steps=20-PointHazard-v0-s{s}" for s in range(3)]
    minutes = int(re.search(r"(\d+) trials, ~(\d+) min on 2 cores", FIRST_SCREEN).group(2))
    assert f"{plan.task}, {plan.n_trials} trials" in FIRST_SCREEN
    assert plan.estimated_wall_s / 60 <= minutes <= 35, (plan.estimated_wall_s / 60, minutes)
    assert "quick" in FIRST_SCREEN and "--space ablation" in FIRST_SCREEN


def test_table_3_itself_is_the_paper_budget_and_says_what_it_costs(tmp_path, monkeypatch, capsys):
    args = cli.parse_args(["--space", "ablation", "--task", "SafetyPointGoal1-v0", "--budget", "paper",
                           "--storage", str(tmp_path / "ray_results")])
    monkeypatch.chdir(tmp_path)
    plan = cli.make_plan(args)
    assert (plan.n_trials, plan.timesteps) == (48, 2_500_000)
    readme_cpu_h = float(re.search(r"~(\d+)\s+CPU-hours by the plan's estimate", README).group(1))
    assert readme_cpu_h == pytest.approx(plan.estimated_cpu_h, rel=0.15)
    cli.print_plan(plan, args)
    out = capsys.readouterr().out
    assert f"{plan.estimated_cpu_h:.1f} CPU-hours" in out and "docker/README.md" in out  # points to a cluster
