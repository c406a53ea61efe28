"""sweeps/reports/ladder.py: R*(b), regrets, ranks and wins from hand-made scores (6 frontier points,
3 limits), each figure computed by hand in the comments."""

import math

import pandas as pd
import pytest

from sweeps.reports import ladder

TASK = "lac/PointHazard-v0"
# The frontier: one seed per fixed ν, (return, cost).
FRONTIER = {"0": (10, 30), "0.5": (8, 20), "1": (6, 12), "2": (4, 8), "4": (2, 3), "8": (1, 1)}
# Two configurations × 3 limits × 2 seeds: (limit, [(return, cost) per seed]).
RUNS = {
    "ppo_lag": {5: [(1.5, 4), (2.5, 6)], 15: [(5, 14), (5, 16)], 25: [(9, 30), (9, 30)]},
    "sac_lag": {5: [(1, 2), (1, 2)], 15: [(7, 10), (5, 12)], 25: [(7, 20), (7, 20)]},
}


def trials() -> pd.DataFrame:
    rows = [{"group": "frontier", "param": "nu_fixed", "value": float(nu), "algo": "ppo_lag", "cost_limit": 25.0,
             "seed": 0, "episode_return": r, "episode_cost": c} for nu, (r, c) in FRONTIER.items()]
    rows += [{"group": "compare", "param": "algo", "value": algo, "algo": algo, "cost_limit": float(b), "seed": s,
              "episode_return": r, "episode_cost": c}
             for algo, by_limit in RUNS.items() for b, seeds in by_limit.items() for s, (r, c) in enumerate(seeds)]
    df = pd.DataFrame(rows)
    return df.assign(task=TASK, status="TERMINATED", config=df["algo"] + "-b" + df["cost_limit"].astype(str))


def test_r_star_is_the_best_return_within_each_limit():
    points = ladder.frontier_points(trials())
    assert len(points) == 6
    # b = 5: costs 3 and 1 are within, returns 2 and 1 → 2 (ν 4); b = 15: 6 (ν 1); b = 25: 8 (ν 0.5).
    stars = {b: ladder.best_within(points, b) for b in (5, 15, 25)}
    assert [(s["r_star"], s["r_star_nu"]) for s in stars.values()] == [(2, "4"), (6, "1"), (8, "0.5")]
    assert math.isnan(ladder.best_within(points, 0.5)["r_star"])  # no point within 0.5


def test_regrets_ranks_and_wins_by_hand():
    table = ladder.ladder_table(trials()).set_index(["algo", "cost_limit"])
    # Means: ppo_lag 2.0 / 5.0 / 9.0 at costs 5 / 15 / 30; sac_lag 1.0 / 6.0 / 7.0 at costs 2 / 11 / 20.
    assert table["return_mean"].to_dict() == {("ppo_lag", 5.0): 2.0, ("ppo_lag", 15.0): 5.0, ("ppo_lag", 25.0): 9.0,
                                              ("sac_lag", 5.0): 1.0, ("sac_lag", 15.0): 6.0, ("sac_lag", 25.0): 7.0}
    # Regret R*(b) − R(b): 2 − 2, 6 − 5, 8 − 9 for ppo_lag; 2 − 1, 6 − 6, 8 − 7 for sac_lag.
    assert table["regret"].to_dict() == {("ppo_lag", 5.0): 0.0, ("ppo_lag", 15.0): 1.0, ("ppo_lag", 25.0): -1.0,
                                         ("sac_lag", 5.0): 1.0, ("sac_lag", 15.0): 0.0, ("sac_lag", 25.0): 1.0}
    # b = 5: both within (5 ≤ 5, 2 ≤ 5), ppo_lag's return higher; b = 15: sac_lag's 6 > 5;
    # b = 25: ppo_lag's cost 30 is over, so sac_lag first though its return is lower.
    assert table["rank"].to_dict() == {("ppo_lag", 5.0): 1, ("ppo_lag", 15.0): 2, ("ppo_lag", 25.0): 2,
                                       ("sac_lag", 5.0): 2, ("sac_lag", 15.0): 1, ("sac_lag", 25.0): 1}
    assert table.loc[("ppo_lag", 5.0), "p_feasible"] == 0.5  # seed costs 4 and 6 against b = 5
    w = ladder.wins(ladder.ladder_table(trials())).set_index("configuration")
    assert w.loc["ppo_lag", ["wins", "limits"]].tolist() == [1, 3] and w.loc["sac_lag", "wins"] == 2
    assert w.loc["ppo_lag", "worst_regret"] == 1.0 and w.loc["ppo_lag", "mean_regret"] == 0.0
    assert w.loc["sac_lag", "mean_regret"] == pytest.approx(2 / 3)


def test_the_ranking_change_is_named_once_and_winners_by_regret():
    table = ladder.ladder_table(trials())
    changes = ladder.ranking_changes(table)
    assert changes == [f"{TASK}: b = 5 → 15: ppo_lag > sac_lag becomes sac_lag > ppo_lag"]  # 15 → 25 keeps it
    assert ladder.choose(table, 1, by="mean") == ["ppo_lag"]  # mean regret 0 against 2/3
    with pytest.raises(ValueError, match="accepted: worst | mean"):
        ladder.choose(table, 1, by="best")
    text = ladder.ladder_markdown(table)
    assert "| 5 | 1 | ppo_lag |" in text and "ranking changes at b = 5 → 15" in text and "2.00 (ν=4)" in text


def test_the_papers_table_is_made_at_each_limit_of_a_ladder(tmp_path):
    """Per limit, one configuration per task and algorithm: the table's layout holds at each; the
    frontier's runs are in none."""
    from sweeps.reports.table import build_table, write_table_report

    parts = ladder.by_limit(trials())
    assert [name for name, _ in parts] == ["table-b5", "table-b15", "table-b25"]
    assert all(set(rows["algo"]) == {"ppo_lag", "sac_lag"} and rows["group"].ne("frontier").all() for _, rows in parts)
    assert build_table(trials()) is None  # all limits in one table: two configurations per cell
    paths, note = write_table_report(parts[0][1], tmp_path / parts[0][0], 40_000)
    assert (tmp_path / "table-b5" / "table.md").read_text() == note and set(paths) >= {"table.md"}
    one = trials()[lambda d: (d["cost_limit"] == 5) & d["group"].ne("frontier")]
    assert [name for name, _ in ladder.by_limit(one)] == [""]
