"""Reports in docs/ rendered by the project's code from the data committed beside them.

An evidence folder commits the trials its sweeps recorded and the reports rendered from them alone:

- a ladder (docs/ladder-pointhazard/): ``trials.csv`` (one row per trial, as the sweep's parent run
  wrote it in ``summary/trials.csv``) → ``ladder.md``, ``ladder.csv``, ``frontier_points.csv``,
  ``ladder.png``;
- a tuned comparison (docs/tuned-pointhazard/): ``sweep.yaml`` (the resolved sweep file with its
  ``tune:``), ``search-ALGO.csv`` (each search's trials with the values it searched) and
  ``confirmation.csv`` (the confirmation's trials), as the run writes them (``tuned-data/`` in the
  confirmation's directory: sweeps/tuned.py ``write_tuned_data``) → ``report.md``, the report the
  run printed.

``python -m sweeps.reports.rendered DIR`` renders a folder again; tests/sweeps/reports/test_rendered.py
does so for every such folder and compares the figures, so a report in docs/ always says what its
data says under the code as it is.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pandas as pd

#: The data a folder's reports are rendered from.
TRIALS = "trials.csv"
#: What a ladder folder's rendering writes (ladder.png beside them).
LADDER_FILES = ("ladder.md", "ladder.csv", "frontier_points.csv")
#: What a tuned folder's rendering writes.
TUNED_REPORT = "report.md"


def read_trials(folder: Path, name: str = TRIALS) -> pd.DataFrame:
    """A folder's trials (``trials.csv``), text columns read as text (a swept value "0.25" stays the
    value the sweep logged, a missing one empty)."""
    return pd.read_csv(Path(folder) / name, dtype={"param": str, "group": str, "config": str, "task": str,
                                                     "algo": str}, keep_default_na=True)


def render_ladder(folder: Path, out: Path | None = None) -> list[Path]:
    """The ladder's reports of ``folder``'s trials, written to ``out`` (default: the folder itself)."""
    from sweeps.reports.ladder import write_ladder_report

    out = Path(out or folder)
    out.mkdir(parents=True, exist_ok=True)
    write_ladder_report(read_trials(folder), out)
    return [out / name for name in (*LADDER_FILES, "ladder.png")]


def render_tuned(folder: Path, out: Path | None = None) -> list[Path]:
    """The tuned comparison's report of ``folder``'s data, written to ``out`` (default: the folder):
    the sweep file planned again (no Ray, a scratch MLflow store), each algorithm's winners chosen
    from its search's trials, the comparison made on the confirmation's (sweeps/tuned.py
    ``tuned_report``, as the run makes it)."""
    from sweeps import sweep_file
    from sweeps.infra import Infra
    from sweeps.tuned import CONFIRMATION, SEARCH, SWEEP, make_tuned_plan, tuned_report

    folder, out = Path(folder), Path(out or folder)
    sweep = sweep_file.load(folder / SWEEP)  # resolved when the run wrote it: planned as it stands
    with tempfile.TemporaryDirectory() as scratch:
        infra = Infra(address=None, address_from=None, tracking_uri=f"sqlite:///{scratch}/mlflow.db", storage=scratch,
                      resume=False, max_failures=0, optuna_seed=0)
        tp = make_tuned_plan(sweep, Path(SWEEP).stem, infra)
    searched = {algo: read_trials(folder, SEARCH.format(algo=algo)) for algo in tp.searches}
    _, _, text = tuned_report(tp, searched, read_trials(folder, CONFIRMATION))
    out.mkdir(parents=True, exist_ok=True)
    (out / TUNED_REPORT).write_text(text)
    return [out / TUNED_REPORT]


def render(folder: Path, out: Path | None = None) -> list[Path]:
    """A folder's reports, by what it holds: a tuned comparison's data, or a ladder's trials."""
    from sweeps.tuned import CONFIRMATION, SWEEP

    folder = Path(folder)
    if (folder / CONFIRMATION).is_file() and (folder / SWEEP).is_file():
        return render_tuned(folder, out)
    if (folder / TRIALS).is_file():
        return render_ladder(folder, out)
    raise ValueError(f"{folder} holds neither {TRIALS} nor {SWEEP} with {CONFIRMATION}; accepted: a ladder's "
                     "folder or a tuned comparison's (sweeps/reports/rendered.py)")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sweeps.reports.rendered", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", help=f"an evidence folder: a ladder's {TRIALS}, or a tuned comparison's sweep.yaml, "
                                  "search-ALGO.csv and confirmation.csv")
    p.add_argument("--out", default=None, help="where to write (default: the folder)")
    args = p.parse_args(argv)
    try:
        paths = render(Path(args.folder), args.out)
    except ValueError as e:
        p.error(str(e))
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
