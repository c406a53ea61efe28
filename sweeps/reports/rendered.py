"""Reports in docs/ rendered by the project's code from the data committed beside them.

An evidence folder (docs/ladder-pointhazard/, ...) commits the trials its sweep recorded
(``trials.csv``: one row per trial, as the sweep's parent run wrote it in ``summary/trials.csv``) and
the reports rendered from that file alone: ``ladder.md``, ``ladder.csv``, ``frontier_points.csv`` and
``ladder.png`` for a ladder. ``python -m sweeps.reports.rendered DIR`` renders them again;
tests/sweeps/reports/test_rendered.py does so for every such folder and compares the figures, so a
report in docs/ always says what its data says under the code as it is.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

#: The data a folder's reports are rendered from.
TRIALS = "trials.csv"
#: What a ladder folder's rendering writes (ladder.png beside them).
LADDER_FILES = ("ladder.md", "ladder.csv", "frontier_points.csv")


def read_trials(folder: Path) -> pd.DataFrame:
    """A folder's ``trials.csv``, its text columns read as text (a swept value "0.25" stays the
    value the sweep logged, a missing one empty)."""
    return pd.read_csv(Path(folder) / TRIALS, dtype={"param": str, "group": str, "config": str, "task": str,
                                                       "algo": str}, keep_default_na=True)


def render_ladder(folder: Path, out: Path | None = None) -> list[Path]:
    """The ladder's reports of ``folder``'s trials, written to ``out`` (default: the folder itself)."""
    from sweeps.reports.ladder import write_ladder_report

    out = Path(out or folder)
    out.mkdir(parents=True, exist_ok=True)
    write_ladder_report(read_trials(folder), out)
    return [out / name for name in (*LADDER_FILES, "ladder.png")]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sweeps.reports.rendered", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", help=f"an evidence folder holding {TRIALS}")
    p.add_argument("--out", default=None, help="where to write (default: the folder)")
    args = p.parse_args(argv)
    if not (Path(args.folder) / TRIALS).is_file():
        p.error(f"{args.folder} has no {TRIALS}; accepted: a folder with the trials its sweep recorded")
    for path in render_ladder(Path(args.folder), args.out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
