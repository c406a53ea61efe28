"""benchmarks/iteration.py --against REV: whole training iterations of another commit's code beside
today's, refused early on bad input."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TASK = "lac/PointHazard-v0"


def _iteration_module():
    spec = importlib.util.spec_from_file_location("iteration", ROOT / "benchmarks" / "iteration.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("argv, message", [
    (["--against", "no-such-revision", "--algos", "ppo_lag"], "--against 'no-such-revision': not a commit"),
    (["--against", "HEAD"], "--against needs --algos, each one of: lac, "),
    (["--against", "HEAD", "--algos", "ppo_lag,nope"], "(got 'ppo_lag,nope')"),
    (["--against", "HEAD", "--algos", "ppo_lag", "--tasks", TASK, "SafetyPointGoal1-v0"], "--against times one task"),
])
def test_against_refuses_bad_input_before_anything_starts(argv, message, capsys):
    with pytest.raises(SystemExit) as e:
        _iteration_module().main(argv)
    assert e.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_against_times_the_iterations_of_another_commits_code_beside_todays(capsys):
    """--against HEAD: the same code on both sides (each child checked to import its own tree's
    lac_rllib), so the ratio of their seconds per env steps is ~1 and both timed the steps asked."""
    code = _iteration_module().main(["--against", "HEAD", "--algos", "ppo_lag", "--tasks", TASK, "--steps", "2000"])
    assert code == 0
    row = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ppo_lag |")][-1]
    cells = [cell.strip() for cell in row.split("|")[2:6]]
    old, new, ratio = (float(c.rstrip("x")) for c in cells[:3])
    rounding = 0.005 + 0.005 / new + 0.005 * old / new**2  # the cells' two decimals
    assert old > 0 and new > 0 and abs(ratio - old / new) <= rounding + 1e-9, row
    assert 0.5 < ratio < 2.0, row  # the same code on both sides
    assert cells[3] == "1 each", row  # 2,000 steps: one of the tiny preset's 2,000-step iterations
    old_rows, new_rows = (float(x) for x in row.split("|")[6].split(" / "))
    assert old_rows == new_rows > 1, row  # one seed, the same code: the same minibatch rows trained
