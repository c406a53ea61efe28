"""benchmarks/pbt_evidence.py: each committed folder of docs/pbt-evidence renders its results.md
again from its CSVs alone, and the README quotes only what those tables say."""

import re
from pathlib import Path

import pytest

from tests.benchmarks.loader import load_benchmark

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = sorted(p.parent for p in (ROOT / "docs" / "pbt-evidence").glob("*/results.md"))


@pytest.fixture(scope="module")
def evidence():
    return load_benchmark("pbt_evidence")


@pytest.mark.parametrize("folder", FOLDERS, ids=[f.name for f in FOLDERS])
def test_a_committed_folder_renders_its_results_from_its_csvs(evidence, folder):
    table = evidence.results(folder, confirm_seeds=5)
    assert set(table["method"]) == set(evidence.METHODS)
    assert evidence.markdown(table) == (folder / "results.md").read_text()
    # Each PBT member carries the schedule its winner replays.
    import pandas as pd

    assert pd.read_csv(folder / "search-pbt.csv")["schedule"].notna().all()


def test_the_readme_quotes_only_its_tables():
    assert FOLDERS
    allowed = set()
    import pandas as pd

    for folder in FOLDERS:
        allowed |= set(re.findall(r"-?[\d,]+(?:\.\d+)?", (folder / "results.md").read_text()))
    for folder in (ROOT / "docs" / "pbt-evidence").iterdir():  # a folder still running has its searches only
        for search in folder.glob("search-*.csv"):  # how many a search drew and stopped, what it spent and scored
            trials = pd.read_csv(search)
            allowed |= {str(len(trials)), str(int(trials["status"].eq("STOPPED").sum())),
                        f"{int(trials['env_steps'].sum()):,}"}
            allowed |= {f"{x:.2f}" for x in [*trials["episode_return"], *trials["episode_cost"]]}
    text = (ROOT / "docs" / "pbt-evidence" / "README.md").read_text()
    tables = text.split("\n## ", 1)[1]  # the folders' sections: their tables and verdicts
    quoted = [q for q in re.findall(r"-?[\d,]+(?:\.\d+)?", tables) if q.strip(",")]
    assert len(quoted) > 20
    extra = {"0", "40,000", "5,000", "250,000", "8", "4", "1", "5", "2", "0.8", "1.0", "10,000", "320,000"}  # v0, sizes
    assert not [q for q in quoted if q.strip(",") not in allowed and q.strip(",") not in extra], quoted
