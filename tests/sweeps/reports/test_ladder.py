"""sweeps/reports/ladder.py: R*(b), regrets, ranks, ties and wins from hand-made scores (4 frontier
points × 4 seeds, 2 configurations × 3 limits × 3 seeds), each figure computed by hand in the
comments. The configurations are made so that the mean-cost rule and the per-seed rule disagree."""

import math

import pandas as pd
import pytest

from sweeps.reports import ladder

TASK = "lac/PointHazard-v0"
# The frontier: per fixed ν, its cost (every seed) and returns on seeds 0-1 (where ν is chosen) and
# seeds 2-3 (where R*(b) is measured).
FRONTIER = {"0": (30, (10, 10), (10, 10)), "1": (12, (6, 6), (5, 7)), "4": (3, (3, 3), (1, 3)),
            "8": (1, (1, 1), (1, 1))}
# Two configurations × 3 limits × 3 seeds: (limit, [(return, cost) per seed]).
RUNS = {
    # b = 5: mean cost 4.67 ≤ 5, but one seed of three is over: infeasible by the per-seed rule.
    "ppo_lag": {5: [(3, 0), (3, 0), (3, 14)], 15: [(6, 10), (6.2, 10), (5.8, 10)],
                25: [(9, 20), (9.1, 20), (8.9, 20)]},
    "sac_lag": {5: [(1, 2), (1.2, 2), (0.8, 2)], 15: [(5, 10), (5.1, 10), (4.9, 10)],
                25: [(7, 20), (7.1, 20), (6.9, 20)]},
}


def trials(runs=RUNS) -> pd.DataFrame:
    rows = [{"group": "frontier", "param": "nu_fixed", "value": float(nu), "algo": "ppo_lag", "cost_limit": 25.0,
             "seed": s, "episode_return": r, "episode_cost": c}
            for nu, (c, choose, measure) in FRONTIER.items() for s, r in enumerate(choose + measure)]
    rows += [{"group": "compare", "param": "algo", "value": algo, "algo": algo, "cost_limit": float(b), "seed": s,
              "episode_return": r, "episode_cost": c}
             for algo, by_limit in runs.items() for b, seeds in by_limit.items() for s, (r, c) in enumerate(seeds)]
    df = pd.DataFrame(rows)
    return df.assign(task=TASK, status="TERMINATED", config=df["algo"] + "-b" + df["cost_limit"].astype(str))


def test_r_star_is_chosen_on_half_the_seeds_and_measured_on_the_rest():
    seeds = ladder.frontier_seeds(trials())
    assert len(ladder.frontier_points(trials())) == 4 and len(seeds) == 16
    # b = 5: ν 4 (cost 3, return 3 on seeds 0-1) beats ν 8; measured on seeds 2-3: (1 + 3) / 2 = 2,
    # not the 3 it was chosen at. b = 15 and 25: ν 1 (6 on seeds 0-1), measured 6.
    stars = {b: ladder.best_within(seeds, b) for b in (5, 15, 25)}
    assert [(s["r_star"], s["r_star_nu"]) for s in stars.values()] == [(2, "4"), (6, "1"), (6, "1")]
    assert list(stars[5]["r_star_scores"]) == [1, 3] and stars[5]["r_star_algo"] == "ppo_lag"
    none = ladder.best_within(seeds, 0.5)  # no ν within 0.5
    assert math.isnan(none["r_star"]) and "no fixed ν is feasible within b = 0.5" in none["why"]


def test_no_r_star_where_the_chosen_nu_fails_the_rule_on_its_held_out_seeds():
    """R*(b) is a feasible reference only if the ν chosen on half the seeds is feasible on the seeds
    that measure it too: ν 4 within b = 5 on seeds 0-1 (cost 3), over it on seeds 2-3, gives none."""
    seeds = ladder.frontier_seeds(trials())
    seeds.loc[(seeds["nu"] == "4") & (seeds["seed"] >= 2), "cost"] = 7.0
    star = ladder.best_within(seeds, 5)
    assert math.isnan(star["r_star"]) and star["r_star_nu"] == "4" and not len(star["r_star_scores"])
    assert star["why"] == "ν = 4, chosen on half the seeds, fails the rule on the held-out ones (0 of 2 within b = 5)"
    seeds.loc[(seeds["nu"] == "4") & (seeds["seed"] == 3), "cost"] = 3.0  # 1 of 2 within: still below 80%
    assert math.isnan(ladder.best_within(seeds, 5)["r_star"])
    assert ladder.best_within(seeds, 15)["r_star"] == 6  # ν 1, feasible on every seed: unchanged


def test_the_per_seed_rule_decides_rank_regret_wins_and_the_choice():
    table = ladder.ladder_table(trials()).set_index(["algo", "cost_limit"])
    assert table["return_mean"].to_dict() == pytest.approx(
        {("ppo_lag", 5.0): 3.0, ("ppo_lag", 15.0): 6.0, ("ppo_lag", 25.0): 9.0,
         ("sac_lag", 5.0): 1.0, ("sac_lag", 15.0): 5.0, ("sac_lag", 25.0): 7.0})
    # ppo_lag at b = 5 is infeasible (2 of 3 seeds): no regret (the old mean-cost rule gave it 2 − 3 = −1
    # and rank 1), its violation instead: (0 + 0 + 9) / 3 = 3.
    assert not table.loc[("ppo_lag", 5.0), "feasible"] and math.isnan(table.loc[("ppo_lag", 5.0), "regret"])
    assert table.loc[("ppo_lag", 5.0), "violation"] == pytest.approx(3.0)
    # Regret R*(b) − R(b) where feasible: sac_lag 2 − 1, 6 − 5, 6 − 7; ppo_lag 6 − 6, 6 − 9.
    assert table["regret"].dropna().to_dict() == pytest.approx(
        {("ppo_lag", 15.0): 0.0, ("ppo_lag", 25.0): -3.0, ("sac_lag", 5.0): 1.0, ("sac_lag", 15.0): 1.0,
         ("sac_lag", 25.0): -1.0})
    # Ranks: b = 5 sac_lag (the only feasible) first; b = 15 a tie (t-intervals [5.2, 6.8] and
    # [4.2, 5.8] overlap); b = 25 ppo_lag's [8.2, 9.8] is wholly above [6.2, 7.8].
    assert table["rank"].to_dict() == {("ppo_lag", 5.0): 2, ("ppo_lag", 15.0): 1, ("ppo_lag", 25.0): 1,
                                       ("sac_lag", 5.0): 1, ("sac_lag", 15.0): 1, ("sac_lag", 25.0): 2}
    w = ladder.wins(ladder.ladder_table(trials())).set_index("configuration")
    assert w.loc["ppo_lag", ["wins", "feasible_at", "limits"]].tolist() == [2, 2, 3] and w.loc["sac_lag", "wins"] == 2
    assert math.isnan(w.loc["ppo_lag", "worst_regret"]) and w.loc["ppo_lag", "why"] == "infeasible at b = 5"
    assert w.loc["sac_lag", "worst_regret"] == pytest.approx(1.0)
    assert w.loc["sac_lag", "mean_regret"] == pytest.approx(1 / 3)
    # The old rule would have chosen ppo_lag by worst regret (0 against 1): an infeasible row is never chosen.
    assert ladder.choose(ladder.ladder_table(trials()), 2, by="worst") == (["sac_lag"], [])


def test_ties_changes_and_the_markdown():
    table = ladder.ladder_table(trials())
    assert ladder.ranking_changes(table) == [
        f"{TASK}: b = 5 → 15: sac_lag > ppo_lag becomes ppo_lag = sac_lag",
        f"{TASK}: b = 15 → 25: ppo_lag = sac_lag becomes ppo_lag > sac_lag"]
    with pytest.raises(ValueError, match="accepted: worst | mean"):
        ladder.choose(table, 1, by="best")
    text = ladder.ladder_markdown(table)
    assert "| 5 | 1 | sac_lag |" in text and "| 15 | 1= | ppo_lag |" in text and "2.00 (ν=4, 2)" in text
    assert "infeasible (over by 3.00)" in text and "ppo_lag's fixed-ν frontier" in text
    assert "Student-t at 98%" in text and "Wilson" in text
    # R*(15) and R*(25) are both ν = 1: the two rungs test the same yardstick, and the report says so.
    assert "R*(b) is the same point (ν = 1) at b = 15 and 25" in text and "at b = 5 and 15" not in text


def test_no_feasible_frontier_point_or_candidate_is_said_in_one_line():
    runs = {"sac_lag": {0.5: [(1, 0), (1, 0), (1, 0)], 5: [(1, 2), (1.2, 2), (0.8, 2)]}}
    chosen, notes = ladder.choose(ladder.ladder_table(trials(runs)), 1, by="worst")
    assert chosen == [] and notes == [f"{TASK}: no configuration has a worst regret to choose by "
                                      "(sac_lag: no R*(b) at b = 0.5)"]
    runs = {"sac_lag": {5: [(1, 9), (1, 9), (1, 0)], 15: [(5, 10), (5.1, 10), (4.9, 10)]}}
    chosen, notes = ladder.choose(ladder.ladder_table(trials(runs)), 1, by="mean")
    assert chosen == [] and "sac_lag: infeasible at b = 5" in notes[0]


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
