"""The golden-step fixture format, shared by the recording scripts (run in a reference's own venv:
numpy and torch only here, nothing of lac_rllib) and read by tests/algorithms/golden.py.

One ``.npz`` per (algorithm, reference): ``meta`` (a JSON string: the reference, its version or
commit, the command that recorded it, the reference's hyperparameters the step used), ``in/<name>``
the step's inputs (the batch, the episode cost fed to the multiplier), ``before/<param>`` the
weights the step started from and ``out/<name>`` what the reference computed (losses, gradients
after the clip, the parameters and the multiplier after the step), in float64."""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np

#: Where the fixtures live: the tests read them from there.
FIXTURES = Path(__file__).resolve().parents[2] / "tests" / "fixtures" / "golden"
#: Keys every fixture's meta must carry; the loader refuses a fixture without them.
REQUIRED_META = ("reference", "reference_version", "algorithm", "command")


def save(path: Path, meta: dict, inputs: dict, before: dict, outputs: dict) -> Path:
    missing = [k for k in REQUIRED_META if not meta.get(k)]
    if missing:
        raise ValueError(f"fixture meta lacks {missing}")
    meta = {**meta, "python": platform.python_version()}
    arrays = {"meta": np.array(json.dumps(meta, sort_keys=True))}
    for prefix, group in (("in", inputs), ("before", before), ("out", outputs)):
        for name, value in group.items():
            arrays[f"{prefix}/{name}"] = _array(value)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB, {len(arrays) - 1} arrays)", file=sys.stderr)
    return path


def _array(value) -> np.ndarray:
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value)
    return arr.astype(np.float64) if arr.dtype.kind == "f" else arr


def run_for_algos(doc: str, names, record) -> None:
    """The command line of a script that records one fixture per algorithm (``--algos`` among
    ``names``, refused in one line otherwise): ``record(algo, out_dir)`` for each."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algos", default=",".join(names))
    parser.add_argument("--out", type=Path, default=FIXTURES)
    args = parser.parse_args()
    algos = args.algos.split(",")
    bad = [a for a in algos if a not in names]
    if bad:
        parser.error(f"--algos {bad}: accepted {sorted(names)}")
    os.environ.setdefault("WANDB_MODE", "disabled")  # a reference's logger must not reach for the network
    for algo in algos:
        record(algo, args.out)


def run_from_mirror(doc: str, repo: str, commit: str, record) -> None:
    """The command line of a script that runs a paper's code from a bare git mirror of ``repo``
    at ``commit``: ``record(mirror, commit, out_dir)``."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mirror", type=Path, required=True, help=f"a bare git repository of {repo}")
    parser.add_argument("--commit", default=commit)
    parser.add_argument("--out", type=Path, default=FIXTURES)
    args = parser.parse_args()
    record(args.mirror, args.commit, args.out)
