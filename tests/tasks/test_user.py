"""A user's own env as a task: what its TaskSpec records of it."""

import sys
from pathlib import Path

import gymnasium as gym
import pytest

from lac_rllib.tasks.user import user_task

USER_ENVS = str(Path(__file__).resolve().parents[1] / "sweeps")  # tests/sweeps/user_envs.py


def test_a_user_tasks_episode_limit_is_its_gymnasium_time_limit_where_it_has_one():
    """The sweep plan counts evaluation episodes at ``episode_steps``: a gymnasium id registered
    with a time limit gives it; a bare factory's env (which may truncate itself) gives the default."""
    gym.register("lactest/Line-v0", entry_point="user_envs:_Line", max_episode_steps=40)
    sys.path.insert(0, USER_ENVS)
    try:
        registered = user_task("user/lactest-line-40", gym_id="lactest/Line-v0", cost_limit=5, cost_key="violation",
                               preset="tiny")
        bare = user_task("user/lactest-line-bare", factory="user_envs:make_safe", cost_limit=5,
                         cost_key="violation", preset="tiny", search_dirs=(USER_ENVS,))
    finally:
        sys.path.remove(USER_ENVS)
    assert registered.episode_steps == 40
    assert bare.episode_steps == 1000


def test_building_a_users_env_is_announced_before_its_code_runs(tmp_path, monkeypatch, capsys):
    """The env is the user's code: said on stderr before it is built and stepped, so a slow or
    hanging constructor is never a silent command."""
    (tmp_path / "chatty_env.py").write_text("import sys\n"
                                            "def make(config):\n    print('constructor runs', file=sys.stderr)\n"
                                            "    raise RuntimeError('no display')\n")
    monkeypatch.setattr(sys, "path", list(sys.path))
    with pytest.raises(ValueError, match="cannot be built"):
        user_task("mine/Chatty-v0", factory="chatty_env:make", cost_limit=1.0, search_dirs=(str(tmp_path),))
    err = capsys.readouterr().err
    said = "lac-rllib: building and stepping your env chatty_env:make (task mine/Chatty-v0)"
    assert said in err and err.index(said) < err.index("constructor runs")
