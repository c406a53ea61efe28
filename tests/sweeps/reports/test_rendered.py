"""A report in docs/ is what the project's code renders from the data beside it
(sweeps/reports/rendered.py), and the figures a README quotes are the report's."""

from pathlib import Path

import numpy as np
import pandas as pd

from sweeps.reports import rendered

DOCS = Path(__file__).resolve().parents[3] / "docs"


def test_a_folder_renders_from_its_trials_alone(tmp_path):
    """The renderer on a folder holding only trials.csv (the hand-made ladder of test_ladder.py):
    what it writes, rendered again from the same file, is the same."""
    from tests.sweeps.reports.test_ladder import trials

    trials().to_csv(tmp_path / rendered.TRIALS, index=False)
    rendered.render_ladder(tmp_path)
    assert "| 5 | 1 | sac_lag |" in (tmp_path / "ladder.md").read_text()
    again = tmp_path / "again"
    rendered.render_ladder(tmp_path, again)
    assert (again / "ladder.md").read_text() == (tmp_path / "ladder.md").read_text()
    for name in ("ladder.csv", "frontier_points.csv"):
        _same_csv(again / name, tmp_path / name)


def _same_csv(a: Path, b: Path) -> None:
    x, y = pd.read_csv(a), pd.read_csv(b)
    assert list(x.columns) == list(y.columns) and len(x) == len(y), a.name
    for col in x.columns:
        if pd.api.types.is_numeric_dtype(x[col]) and pd.api.types.is_numeric_dtype(y[col]):
            np.testing.assert_allclose(x[col].to_numpy(float), y[col].to_numpy(float), rtol=1e-9, atol=1e-12,
                                       equal_nan=True, err_msg=f"{a.name}: {col}")
        else:
            assert x[col].fillna("").astype(str).tolist() == y[col].fillna("").astype(str).tolist(), (a.name, col)


def test_the_readmes_default_ablation_figures_are_the_verdicts_of_its_trials():
    """README's paragraph on the default ablation quotes intervals and ties computed by
    sweeps/reports/verdicts.py from docs/sweeps-default/trials.csv."""
    from sweeps.reports import verdicts

    trials = pd.read_csv(DOCS / "sweeps-default" / "trials.csv")
    readme = (DOCS.parent / "README.md").read_text()

    def text(group, value):
        d = trials[(trials["group"] == group) & (trials["value"] == value)]
        m, lo, hi = verdicts.mean_interval(d["episode_return"])
        return f"{m:.2f} [{lo:.2f}, {hi:.2f}]".replace("-", "−")

    assert text("NI", 30) in readme and text("VT", 20) in readme
    rows = trials[trials["group"] != "unconstrained"].groupby(["group", "value"])["episode_return"]
    stats = {k: verdicts.mean_interval(v) for k, v in rows}
    best = stats[("NI", 30.0)]
    ties = sorted(f"{g} {v:g}" for (g, v), (_, lo, hi) in stats.items() if hi >= best[1] and (g, v) != ("NI", 30.0))
    assert ties == ["NI 20", "PR 0.5", "VT 20", "VT 30"], ties  # the README names these as tied


def test_the_committed_ladder_is_rendered_from_its_trials(tmp_path):
    folder = DOCS / "ladder-pointhazard"
    rendered.render(folder, tmp_path)
    assert (tmp_path / "ladder.md").read_text() == (folder / "ladder.md").read_text()
    for name in ("ladder.csv", "frontier_points.csv"):
        _same_csv(tmp_path / name, folder / name)


def test_the_ladders_verdicts_quote_only_what_its_data_says():
    """Every number in docs/ladder-pointhazard/README.md's verdicts is printed by ladder.md, or is a
    frontier point's or a trial's figure rounded (to 1 or 2 decimals)."""
    import re

    folder = DOCS / "ladder-pointhazard"
    text = (folder / "README.md").read_text().replace("−", "-")
    verdicts = text.split("## Verdicts", 1)[1].split("\n## ", 1)[0]
    allowed = set(re.findall(r"-?\d+(?:\.\d+)?", (folder / "ladder.md").read_text()))
    points, trials = pd.read_csv(folder / "frontier_points.csv"), pd.read_csv(folder / "trials.csv")
    for x in [*points["return_mean"], *points["cost_mean"], *trials["episode_cost"], *trials["episode_return"]]:
        allowed |= {f"{x:.1f}", f"{x:.2f}"}
    quoted = re.findall(r"-?\d+(?:\.\d+)?", verdicts)
    assert len(quoted) > 50
    assert not [q for q in quoted if q not in allowed]


def test_the_committed_tuned_comparison_is_rendered_from_its_data(tmp_path):
    folder = DOCS / "tuned-pointhazard"
    rendered.render(folder, tmp_path)
    assert (tmp_path / "report.md").read_text() == (folder / "report.md").read_text()


def test_the_tuned_comparisons_verdicts_quote_only_what_its_data_says():
    """Every number in docs/tuned-pointhazard/README.md's verdicts is printed by report.md, or is a
    confirmation seed's return or cost rounded to 2 decimals."""
    import re

    folder = DOCS / "tuned-pointhazard"
    text = (folder / "README.md").read_text().replace("−", "-")
    verdicts = text.split("## Verdicts", 1)[1].split("\n## ", 1)[0]
    allowed = set(re.findall(r"-?\d+(?:\.\d+)?", (folder / "report.md").read_text()))
    trials = pd.read_csv(folder / "confirmation.csv")
    allowed |= {f"{x:.2f}" for x in [*trials["episode_return"], *trials["episode_cost"]]}
    quoted = re.findall(r"-?\d+(?:\.\d+)?", verdicts)
    assert len(quoted) > 40
    assert not [q for q in quoted if q not in allowed]
