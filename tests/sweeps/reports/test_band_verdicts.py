"""The one rule for "within a reference band" (sweeps/reports/published.py ``band_verdict``), and the
500k baselines report (docs/fidelity/pointgoal1-baselines-500k/) saying what that rule returns on its
committed curves.csv: each algorithm's mean ± std, its distance from OmniSafe's curve and its verdict
in the README's table and prose, and the summary in docs/fidelity/README.md. No Ray."""

import re
from pathlib import Path

import pandas as pd
import pytest

from sweeps.reports.published import band_verdict, published

DOCS = Path(__file__).resolve().parents[3] / "docs" / "fidelity"
REPORT = DOCS / "pointgoal1-baselines-500k"
TASK, STEPS = "SafetyPointGoal1-v0", 500_000
#: The README's window: the iterations past 450k up to the 500k budget.
LOW, HIGH = 450_000, 500_000
#: Our algorithm name → the name the README prints.
NAMES = {"ppo_lag": "PPO-Lag", "sac_lag": "SAC-Lag", "focops": "FOCOPS", "cup": "CUP", "p3o": "P3O",
         "trpo_lag": "TRPO-Lag", "cpo": "CPO", "pcpo": "PCPO", "respo": "RESPO"}


# ---------------------------------------------------------------- the rule


@pytest.mark.parametrize("scores, word, side, phrase", [
    ([9.0, 10.0, 11.0], "within", None, "within"),
    ([8.0, 9.0, 10.0], "within", None, "within"),  # the mean on the band's edge (10 ± 1): closed
    ([7.0, 8.0, 9.0], "overlaps", "below", "overlaps, mean below"),  # 8 ± 1 reaches 9
    ([11.5, 12.0, 12.5], "outside", "above", "above"),  # 12 ± 0.5 stops short of 11
    ([3.0, 5.0, 7.0], "outside", "below", "below"),  # 5 ± 2 stops short of 9
    ([12.5], "outside", "above", "above"),  # one seed: no spread to overlap with
])
def test_the_rule_is_the_mean_in_the_band_and_overlap_is_a_word_of_its_own(scores, word, side, phrase):
    v = band_verdict(scores, 10.0, 1.0)
    assert (v.word, v.side, v.phrase) == (word, side, phrase)
    assert v.delta == pytest.approx(v.mean - 10.0)


def test_a_wide_spread_overlaps_whatever_the_mean():
    v = band_verdict([0.0, 30.0, 60.0], 50.0, 2.0)  # mean 30, 20 below the band; SD 30 reaches 60
    assert v.phrase == "overlaps, mean below" and v.sd == pytest.approx(30.0)


def test_no_seed_or_a_negative_tolerance_is_refused():
    with pytest.raises(ValueError, match="at least one"):
        band_verdict([], 1.0, 1.0)
    with pytest.raises(ValueError, match="tolerance"):
        band_verdict([1.0], 1.0, -1.0)


# ---------------------------------------------------------------- the 500k report against its data


def _seed_scores() -> dict[str, pd.DataFrame]:
    curves = pd.read_csv(REPORT / "curves.csv")
    window = curves[(curves["env_steps"] > LOW) & (curves["env_steps"] <= HIGH)]
    return {algo: rows.groupby("seed").agg(ret=("episode_return", "mean"), cost=("episode_cost", "mean"),
                                           n=("iteration", "size"))
            for algo, rows in window.groupby("variant")}


SCORES = _seed_scores()


def _verdicts(algo):
    """(reading, return verdict, cost verdict) of ``algo`` against OmniSafe's curve at 500k, or None."""
    figure = published().find("omnisafe", TASK, algo)
    reading = figure.at(STEPS) if figure else None
    if reading is None:
        return None
    s = SCORES[algo]
    return (reading, band_verdict(s["ret"], reading.return_, reading.tolerance.return_),
            band_verdict(s["cost"], reading.cost, reading.tolerance.cost))


def _text(path: Path) -> str:
    return path.read_text(encoding="utf-8").replace("−", "-")


def _table_rows() -> dict[str, list[str]]:
    """The README's results table: the printed name → its cells."""
    rows = {}
    for line in _text(REPORT / "README.md").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| ") and cells[0] in NAMES.values():
            rows[cells[0]] = cells
    return rows


def _paragraph(name: str) -> str:
    """The README's paragraph on ``name`` (it opens with **NAME.**), on one line."""
    text = _text(REPORT / "README.md")
    found = re.search(rf"^\*\*{re.escape(name)}\.\*\*(.*?)(?:\n\n|\Z)", text, re.S | re.M)
    assert found, f"no paragraph on {name}"
    return " ".join(found.group(1).split())


def _both_within() -> list[str]:
    return [NAMES[a] for a in SCORES if (v := _verdicts(a)) and v[1].word == v[2].word == "within"]


def _names(listed: str) -> set[str]:
    return {n.strip() for n in re.split(r",|\band\b", listed) if n.strip()}


def test_the_window_is_the_one_the_readme_states():
    # 450k < env steps <= 500k: 3 on-policy iterations, 25 of SAC-Lag, RESPO's one at 480k (its 510k
    # iteration left out), 3 seeds each.
    for algo, s in SCORES.items():
        assert list(s.index) == [0, 1, 2], algo
        assert set(s["n"]) == {25 if algo == "sac_lag" else 1 if algo == "respo" else 3}, algo


@pytest.mark.parametrize("algo", list(NAMES))
def test_the_readme_table_says_what_the_rule_returns_on_curves_csv(algo):
    row = _table_rows()[NAMES[algo]]
    s = SCORES[algo]
    _, seeds, ret, cost, curve, delta, verdict = row
    assert seeds == str(len(s))
    assert ret == f"{s['ret'].mean():.2f} ± {s['ret'].std():.2f}"
    assert cost == f"{s['cost'].mean():.1f} ± {s['cost'].std():.1f}"
    found = _verdicts(algo)
    if found is None:
        assert (curve, delta, verdict) == ("not in OmniSafe", "–", "no reference at 500k")
        return
    reading, r, c = found
    assert curve == (f"{reading.return_:g} ± {reading.tolerance.return_:g} / "
                     f"{reading.cost:g} ± {reading.tolerance.cost:g}")
    assert delta == f"{r.delta:+.2f} / {c.delta:+.1f}"
    assert verdict == f"return {r.phrase}; cost {c.phrase}"


@pytest.mark.parametrize("algo", [a for a in NAMES if a != "respo"])
def test_each_algorithms_paragraph_uses_the_rules_words(algo):
    _, r, c = _verdicts(algo)
    text = _paragraph(NAMES[algo])
    assert f"return {r.phrase}" in text and f"cost {c.phrase}" in text


def test_the_summaries_name_exactly_the_algorithms_within_in_both():
    expected = set(_both_within())
    assert expected == {"SAC-Lag", "CPO", "PCPO"}  # by the means on curves.csv
    readme = " ".join(_text(REPORT / "README.md").split())
    listed = re.search(r"(\d+) of the (\d+) algorithms are within in both return and cost: ([^.]+)\.", readme)
    assert listed and _names(listed.group(3)) == expected
    assert (int(listed.group(1)), int(listed.group(2))) == (len(expected), len(SCORES) - 1)  # RESPO: no curve
    index = " ".join(_text(DOCS / "README.md").split())
    row = re.search(r"return and cost within for ([^;]+);", index)
    assert row and _names(row.group(1)) == expected


def test_no_report_calls_an_overlap_within():
    # "within" is the mean in the band; the seeds' spread reaching it is "overlaps".
    for path in (REPORT / "README.md", DOCS / "README.md", DOCS / "pointgoal1-focops-indicator" / "README.md"):
        text = " ".join(_text(path).split())
        assert not re.search(r"within,? (by )?the seeds' spread", text), path
        assert "within by the seeds" not in text, path


def test_the_commands_are_one_per_run():
    block = _text(REPORT / "table.md").split("```")[1]
    runs = [(m.group(2), int(m.group(1))) for m in re.finditer(r"--seed (\d+) .*--algo (\w+)", block)]
    assert sorted(runs) == sorted((a, seed) for a in NAMES for seed in (0, 1, 2))
    # The two commands no row uses: the per-row FOCOPS seed 0 and PCPO seed 0 before the half-step fix.
    assert "pointgoal1-first-order/runs/focops/seed0" not in block
    assert "pointgoal1-trust-region/runs/pcpo/seed0" not in block
