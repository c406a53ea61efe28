"""sweeps/calibrate.py: a task's cost range from a random policy and the unconstrained algorithm, and
the ladder proposed inside it; on the tiny task and on a user's env."""

import sys
from pathlib import Path

import pytest
import yaml

from sweeps import calibrate

USER_ENVS = str(Path(__file__).resolve().parent)  # tests/sweeps/user_envs.py


def test_the_ladder_rises_from_the_low_end_short_of_the_high_one():
    assert calibrate.propose_ladder(2.0, 10.0, 4, zero=False) == [2.0, 4.0, 6.0, 8.0]
    assert calibrate.propose_ladder(10.0, 2.0, 4, zero=True) == [0.0, 2.0, 4.7, 7.3]  # either order; 0 first
    assert calibrate.propose_ladder(3.0, 3.0, 3, zero=False) == [3.0]  # no range: one limit, not three copies


def test_the_frontier_spans_the_scale_where_return_and_cost_trade():
    # gain 11 over a random policy for a cost of 9: nu* = 1.22; the grid 0, nu*/16 .. 2 nu*.
    nu = calibrate.propose_frontier(11.0, 9.0)
    assert nu[0] == 0.0 and nu[1] == pytest.approx(11 / 9 / 16, rel=0.03)  # rounded to 2 figures
    assert nu[-1] == pytest.approx(22 / 9, rel=0.03)
    assert len(nu) == 7 and nu == sorted(set(nu))
    assert calibrate.propose_frontier(11.0, 0.0) == [0.0] and calibrate.propose_frontier(-1.0, 9.0) == [0.0]
    assert calibrate.round2(0.012345) == 0.012 and calibrate.round2(1234.0) == 1200.0


def _run(capsys, *argv):
    try:
        code = calibrate.main(list(argv))
    except SystemExit as e:
        code = e.code
    return code, *capsys.readouterr()


@pytest.mark.slow
def test_calibrate_the_tiny_task(tmp_path, capsys):
    out = tmp_path / "ladder.yaml"
    code, stdout, _ = _run(capsys, "--task", "lac/PointHazard-v0", "--algo", "ppo_lag", "--timesteps", "6000",
                           "--episodes", "6", "--out", str(out))
    text = out.read_text()
    ladder = yaml.safe_load(text)["cost_limits"]
    assert code == 0 and "random policy" in stdout and text in stdout
    assert ladder == sorted(set(ladder)) and 3 <= len(ladder) <= 4  # increasing, distinct (rounding may merge)
    rand, free = (float(x.split()[0].rstrip(";")) for x in
                  (text.split("cost ")[1], text.split("(6,000 env steps) ")[1]))
    positive = [b for b in ladder if b > 0]
    assert min(rand, free) * 0.95 <= positive[0] and max(positive) < max(rand, free), (ladder, rand, free)
    frontier = yaml.safe_load(text)["frontier"]  # the fixed-nu values proposed beside the ladder
    assert frontier["algo"] == "ppo_lag" and frontier["nu"][0] == 0 and len(frontier["nu"]) >= 2


@pytest.mark.slow
def test_calibrate_a_users_env_through_its_factory(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.yaml").write_text("task: {factory: 'user_envs:make_safe', cost_limit: 5, cost_key: violation, "
                                        "preset: tiny, name: mine/Line-v0}\nalgo: ppo_lag\n")
    (tmp_path / "user_envs.py").write_text(Path(USER_ENVS, "user_envs.py").read_text())
    code, stdout, err = _run(capsys, "--config", "mine.yaml", "--timesteps", "2000", "--episodes", "3")
    assert code == 0, err
    assert "building and stepping your env user_envs:make_safe" in err  # said before the factory runs
    assert "mine/Line-v0: random policy" in stdout and "ppo_lag with nu = 0" in stdout
    ladder = yaml.safe_load((tmp_path / "calibrate-mine_Line-v0.yaml").read_text())["cost_limits"]
    assert ladder == sorted(ladder) and ladder


@pytest.mark.parametrize("argv,needle", [
    (["--task", "lac/Nowhere-v0"], "lac/Nowhere-v0"),
    (["--task", "lac/PointHazard-v0", "--algo", "p3o"], "--algo p3o has no Lagrange multiplier to pin at 0; accepted:"),
    (["--task", "lac/PointHazard-v0", "--limits", "1"], "--limits 1 is invalid; accepted: an integer >= 2"),
])
def test_bad_arguments_are_one_line_before_anything_runs(capsys, argv, needle):
    code, _, err = _run(capsys, *argv)
    assert code == 2 and needle in err and err.count("\n") == 1, err


@pytest.mark.slow
def test_calibrate_a_ladder_along_one_constraint(tmp_path, capsys):
    """--constraint lane: both runs' costs are the lane's alone (a random walk from near the x axis
    pays about half its steps; the hazard, ~1, left out), and the snippet runs a ladder along it."""
    out = tmp_path / "lane.yaml"
    code, stdout, err = _run(capsys, "--task", "lac/PointTwoCosts-v0", "--constraint", "lane", "--algo", "ppo_lag",
                             "--timesteps", "2000", "--episodes", "4", "--out", str(out))
    assert code == 0, err
    snippet = yaml.safe_load(out.read_text())
    assert snippet["ladder_constraint"] == "lane" and snippet["cost_limits"] == sorted(snippet["cost_limits"])
    rand = float(out.read_text().split("cost ")[1].split()[0])
    from lac_rllib.tasks import get_task

    summed, _, _ = calibrate.random_episode_costs(get_task("lac/PointTwoCosts-v0"), 4, 0)
    lane, _, _ = calibrate.random_episode_costs(get_task("lac/PointTwoCosts-v0"), 4, 0, "lane")
    hazard, _, _ = calibrate.random_episode_costs(get_task("lac/PointTwoCosts-v0"), 4, 0, "hazard")
    assert rand == pytest.approx(sum(lane) / 4, rel=1e-2) and lane != summed
    assert [a + b for a, b in zip(lane, hazard)] == pytest.approx(summed)


def test_a_constraint_the_task_lacks_is_refused_before_anything_runs(capsys):
    code, _, err = _run(capsys, "--task", "lac/PointTwoCosts-v0", "--constraint", "vases")
    assert code == 2 and "--constraint vases: lac/PointTwoCosts-v0 has no constraint 'vases'; accepted: hazard, lane" \
        in err and err.count("\n") == 1, err
