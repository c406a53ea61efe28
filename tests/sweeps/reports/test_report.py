"""Tests for sweeps/reports/report.py (pure pandas/matplotlib, no Ray)."""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sweeps.reports import report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NAN = math.nan


def _trial(tid, value, seed, ret, cost, group="VT", param="langevin_steps", status="TERMINATED",
           limit=25.0, task="PointGoal1"):
    feasible = float(cost <= limit) if not math.isnan(cost) else NAN
    return dict(trial_id=tid, group=group, param=param, value=value, task=task, seed=seed,
                status=status, episode_return=ret, episode_cost=cost, cost_limit=limit,
                feasible=feasible, objective=ret if feasible == 1.0 else ret - 100, lr=3e-4)


def hand_table(limit=25.0):
    rows = [
        _trial("a0", 10, 0, 10.0, 20.0, limit=limit),
        _trial("a1", 10, 1, 12.0, 24.0, limit=limit),
        _trial("a2", 10, 2, 14.0, 28.0, limit=limit),
        _trial("a3", 10, 3, NAN, NAN, status="ERROR", limit=limit),
        _trial("a4", 10, 4, NAN, 5.0, limit=limit),  # finished but no return: counts as failed
        _trial("a5", 10, 5, 99.0, 1.0, status="ERROR", limit=limit),  # errored late, stale metrics
        _trial("b0", 20, 0, 30.0, 40.0, limit=limit),  # highest return, infeasible
        _trial("b1", 20, 1, 32.0, 44.0, limit=limit),
        _trial("c0", 30, 0, 20.0, 10.0, limit=limit),  # single seed, feasible
        _trial("d0", 100, 0, NAN, NAN, status="ERROR", limit=limit),
        _trial("n0", 50, 0, 1.0, 1.0, group="NI", limit=limit),
    ]
    return pd.DataFrame(rows)


def sweep():
    """NI/VT/PR ablations (several values × 2-3 seeds), a 'paper' group and one errored trial."""
    rng = np.random.default_rng(0)
    rows, curves = [], {}
    spec = {"NI": ("langevin_steps", [30, 50, 100, 200], 3), "VT": ("langevin_steps", [10, 20, 40], 2),
            "PR": ("beta", [0.0, 1.0, 5.0, 20.0], 3), "paper": ("", [None], 3)}
    for group, (param, values, n) in spec.items():
        for vi, v in enumerate(values):
            for s in range(n):
                tid = f"{group}_{v}_{s}"
                steps = np.arange(1, 21 + s) * 5000.0  # seeds of unequal length
                ret = 15 * (1 - np.exp(-steps / 3e4)) + vi + rng.normal(0, 1, steps.size)
                cost = 60 * np.exp(-steps / 4e4) + 15 + 3 * vi + rng.normal(0, 2, steps.size)
                curves[tid] = pd.DataFrame(dict(env_steps=steps, episode_return=ret,
                                                episode_cost=cost, cost_limit=25.0))
                rows.append(_trial(tid, v, s, ret[-1], cost[-1], group=group, param=param))
    rows.append(_trial("VT_err", 50, 9, NAN, NAN, status="ERROR"))
    return pd.DataFrame(rows), curves


def assert_png(path):
    p = Path(path)
    assert p.exists() and p.stat().st_size > 1024
    assert p.read_bytes()[:8] == PNG_MAGIC


def test_summarize_statistics_and_order():
    s = report.summarize(hand_table())
    assert list(zip(s["group"], s["value"])) == [("NI", 50), ("VT", 10), ("VT", 20), ("VT", 30), ("VT", 100)]
    r = s[(s["group"] == "VT") & (s["value"] == 10)].iloc[0]
    assert (r["n_seeds"], r["n_failed"]) == (3, 3)
    assert r["return_mean"] == pytest.approx(12.0) and r["return_std"] == pytest.approx(2.0)
    assert r["cost_mean"] == pytest.approx(24.0) and r["cost_std"] == pytest.approx(4.0)
    # Mean cost 24 ≤ 25, but one seed of three is over: not feasible by the one rule (≥ 80% of seeds).
    assert r["feasible_fraction"] == pytest.approx(2 / 3) and not bool(r["feasible"])
    assert r["cost_limit"] == 25.0 and r["objective_mean"] == pytest.approx((10 + 12 + 14 - 100) / 3)
    single = s[s["value"] == 30].iloc[0]
    assert single["n_seeds"] == 1 and math.isnan(single["return_std"])
    dead = s[s["value"] == 100].iloc[0]
    assert (dead["n_seeds"], dead["n_failed"]) == (0, 1)
    assert math.isnan(dead["return_mean"]) and not bool(dead["feasible"])
    assert not bool(s[s["value"] == 20].iloc[0]["feasible"])


def test_a_ladders_rows_go_by_limit_whatever_order_the_trials_came_in():
    """MLflow lists child runs in the order they ran; the summary must not follow it."""
    ladder = pd.concat([hand_table(limit).assign(config=lambda d, b=limit: d["value"].astype(str) + f"-b{b:g}")
                        for limit in (25.0, 5.0)], ignore_index=True)
    s = report.summarize(ladder)
    vt10 = s[(s["group"] == "VT") & (s["value"] == 10)]
    assert list(vt10["cost_limit"]) == [5.0, 25.0] and list(vt10["config"]) == ["10-b5", "10-b25"]
    shuffled = ladder.sample(frac=1.0, random_state=0).reset_index(drop=True)
    pd.testing.assert_frame_equal(report.summarize(shuffled), s)


def test_best_configuration_prefers_feasible_and_none_when_infeasible():
    best = report.best_configuration(report.summarize(hand_table()))
    assert (best["group"], best["value"], best["return_mean"]) == ("VT", 30, 20.0)
    assert best["return_std"] is None  # NaN std becomes JSON null
    json.dumps(best)  # plain Python types only
    assert report.best_configuration(report.summarize(hand_table(limit=0.5))) is None


def test_over_a_ladder_the_best_is_named_per_limit():
    """Returns at different limits do not compare: one best per limit, named by its configuration."""
    ladder = pd.concat([hand_table(limit).assign(config=lambda d, b=limit: d["value"].astype(str) + f"-b{b:g}")
                        for limit in (25.0, 45.0)], ignore_index=True)
    lines = report.best_lines(report.summarize(ladder))
    # At 25: VT 30 (return 20, cost 10); at 45 VT 20 is feasible too (costs 40, 44) and its return 31 leads.
    assert lines[0].startswith("**Best feasible configuration at limit 25:** VT langevin_steps=30") and len(lines) == 2
    assert lines[1].startswith("**Best feasible configuration at limit 45:** VT langevin_steps=20")


def test_markdown_table():
    s = report.summarize(hand_table())
    md = report.markdown_table(s)
    assert ("| group | configuration | task | seeds | return mean [95%] | return IQM | cost mean [95%] "
            "| cost IQM | feasible seeds | P(return > default) | P(cost < default) | return (mean ± std) "
            "| cost (mean ± std) | limit |") in md
    body = [ln for ln in md.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    assert len(body) == len(s) == 5
    vt10 = next(ln for ln in body if ln.startswith("| VT | langevin_steps=10 |"))
    assert vt10.startswith("| VT | langevin_steps=10 | PointGoal1 | 3 (+3 failed) | 12.00 [3.96, 20.04] | 12.00 |")
    assert vt10.endswith("| 2/3 | – | – | 12.00 ± 2.00 | 24.00 ± 4.00 | 25.00 |")  # no default in this sweep
    assert "20.00 [–]" in md and "20.00 ± –" in md and "nan" not in md.lower()
    assert "| 0 (+1 failed) | – | – | – | – | no (all failed) | – | – | – | – | 25.00 |" in md
    assert "over 1-3 seeds per configuration" in md and "**Warning: fewer than 5 seeds" in md
    assert "Student-t at 98%" in md and "Wilson" in md  # what each interval is
    assert "**Best feasible configuration:** VT langevin_steps=30 on PointGoal1" in md
    assert "none" in report.markdown_table(report.summarize(hand_table(limit=0.5))).splitlines()[-1]


def test_configurations_are_compared_with_the_default():
    df = hand_table()
    df["default"] = df["value"].eq(20)  # VT T=20 plays LAC's defaults: returns 30, 32; costs 40, 44
    s = report.summarize(df).set_index("value")
    assert bool(s.loc[20, "is_default"]) and s.loc[20, "poi_return_vs_default"] == 0.5
    assert s.loc[10, "poi_return_vs_default"] == 0.0 and s.loc[10, "poi_cost_vs_default"] == 1.0
    assert "| langevin_steps=20 (default) |" in report.markdown_table(s.reset_index())


def test_plots_write_pngs(tmp_path):
    trials, curves = sweep()
    assert_png(report.cost_box_plots(trials, tmp_path / "box.png"))
    assert_png(report.learning_curves(trials, curves, tmp_path / "curves.png"))
    assert_png(report.trial_curve(curves["VT_10_0"], tmp_path / "one.png", "VT_10_0"))
    assert_png(report.aggregate_plots(report.summarize(trials), tmp_path / "aggregates.png"))


def test_plots_return_none_when_nothing_to_plot(tmp_path):
    trials, curves = sweep()
    unswept = trials[trials["group"] == "paper"]
    assert report.cost_box_plots(unswept, tmp_path / "a.png") is None
    assert report.cost_box_plots(trials[trials["status"] == "ERROR"], tmp_path / "b.png") is None
    assert report.learning_curves(trials, {}, tmp_path / "c.png") is None
    assert not any(tmp_path.iterdir())


def test_write_sweep_reports(tmp_path):
    trials, curves = sweep()
    for field, other in (("langevin_steps", 20), ("beta", 1.0)):  # each trial's value of the swept fields
        trials[field] = [v if p == field else other for p, v in zip(trials["param"], trials["value"])]
    paths = report.write_sweep_reports(trials, curves, tmp_path / "out", fields=("langevin_steps", "beta"))
    names = {"summary.csv", "summary.md", "best.json", "trials.csv", "cost_boxplots.png", "learning_curves.png",
             "aggregates.png", "frontier.png", "frontier.html", "importance.png", "importance.html",
             *(f"{k}_{o}.png" for k in ("parallel", "slice") for o in ("return", "cost"))}
    assert set(paths) == names and all(Path(p).exists() for p in paths.values())
    n_configs = 4 + 4 + 4 + 1  # NI + VT (incl. the all-errored value 50) + PR + paper
    summary = pd.read_csv(paths["summary.csv"])
    assert len(summary) == n_configs
    # The safety statistics and the frontier are columns of the summary, and summary.md shows them.
    assert {"p_feasible", "p_feasible_low", "violation_total", "worst_excess", "on_frontier", "chain_flags"} <= set(
        summary.columns)
    feasible = summary[summary["n_seeds"] > 0]
    assert ((feasible["p_feasible_low"] <= feasible["p_feasible"]) & (feasible["p_feasible"] <= feasible[
        "p_feasible_high"])).all()
    assert summary.loc[summary["on_frontier"], "feasible"].all() and summary["on_frontier"].any()
    md = Path(paths["summary.md"]).read_text()
    assert "**Safety per configuration**" in md and "**Hyperparameter importance**" in md
    assert len(pd.read_csv(paths["trials.csv"])) == len(trials)
    best = json.loads(Path(paths["best.json"]).read_text())
    assert best["feasible"] is True and best["n_seeds"] >= 2
    assert_png(paths["learning_curves.png"])


def test_a_compare_sweep_puts_every_algorithm_beside_lac():
    """P(LAC beats X) is read off the hand-made seeds (U statistic, ties one half); the best
    algorithm within the limit is the feasible one with the most return, not the top return."""
    rows = [_trial(f"c{s}", "cup", s, 1.0, 0.0, group="compare", param="algo", limit=2.0) for s in range(2)]
    rows += [_trial(f"l{s}", "lac", s, r, c, group="compare", param="algo", limit=2.0)
             for s, (r, c) in enumerate([(10.0, 1.0), (12.0, 1.5), (14.0, 0.5)])]
    rows += [_trial(f"p{s}", "ppo_lag", s, r, c, group="compare", param="algo", limit=2.0)
             for s, (r, c) in enumerate([(11.0, 0.2), (8.0, 0.1), (9.0, 0.3)])]  # LAC returns beat 8 of 9 pairs
    rows += [_trial(f"s{s}", "sac_lag", s, r, c, group="compare", param="algo", limit=2.0)
             for s, (r, c) in enumerate([(30.0, 9.0), (31.0, 8.0), (29.0, 7.0)])]  # most return, infeasible
    df = pd.DataFrame(rows)
    df["default"] = df["value"].eq("lac")
    text = report.algorithm_comparison(report.summarize(df))
    ppo = next(line for line in text.splitlines() if line.startswith("| ppo_lag |"))
    cells = [c.strip() for c in ppo.strip("|").split("|")]
    assert cells[-2:] == [f"{8 / 9:.2f}", "0.00"]  # LAC's return beats PPO-Lag's in 8 of 9 pairs; its cost never
    sac = next(line for line in text.splitlines() if line.startswith("| sac_lag |"))
    assert [c.strip() for c in sac.strip("|").split("|")][-2:] == ["0.00", "1.00"]
    assert "**Best within the limit:** lac, return 12.00" in text
    assert "| lac | 3 |" in text and "– | – |" in text.split("| lac |")[1].splitlines()[0]
    listed = [line.split("|")[1].strip() for line in text.splitlines() if line.startswith("| ") and "seeds" not in line]
    assert listed == ["lac", "ppo_lag", "sac_lag", "cup"]  # the registry's order, LAC first (not by name)
    assert report.algorithm_comparison(report.summarize(hand_table())) == ""  # no algorithms compared


def test_the_parent_runs_metrics_name_the_best_feasible_configuration_and_the_counts():
    # VT 10: mean cost 24 <= 25 but 2 of 3 seeds: infeasible; VT 20 infeasible; VT 30 and NI 50 feasible.
    summary = report.summarize(hand_table())
    m = report.parent_metrics(summary)
    assert set(m) == set(report.PARENT_METRICS)
    assert m["best_feasible_return"] == pytest.approx(20.0) and m["best_feasible_cost"] == pytest.approx(10.0)
    assert m["feasible_configurations"] == 2 and m["configurations"] == 5
    assert (m["trials_finished"], m["trials_failed"], m["trials_stopped"]) == (7, 4, 0)
    # Nothing feasible: no best (the sweep sorts last), the counts still there.
    none = report.parent_metrics(report.summarize(hand_table(limit=0.5)))
    assert "best_feasible_return" not in none and none["feasible_configurations"] == 0
    # Two tasks: the best per task, not one across tasks.
    two = pd.concat([hand_table(), hand_table().assign(task="CarGoal1", episode_return=lambda d: d.episode_return * 2)],
                    ignore_index=True)
    per_task = report.parent_metrics(report.summarize(two))
    assert per_task["best_feasible_return/PointGoal1"] == pytest.approx(20.0)
    assert per_task["best_feasible_return/CarGoal1"] == pytest.approx(40.0) and "best_feasible_return" not in per_task


def test_when_nothing_is_feasible_the_note_says_so_first_and_names_the_least_infeasible():
    summary = report.summarize(hand_table(limit=0.5))  # every configuration over 0.5
    line = report.nothing_feasible_markdown(summary)
    assert line.startswith("**Nothing is feasible**") and "NI" in line and "0.50 over" in line, line
    assert report.nothing_feasible_markdown(report.summarize(hand_table())) == ""  # something is: no line

