"""The golden-step fixture format, shared by the recording scripts (run in a reference's own venv:
numpy and torch only here, nothing of lac_rllib) and read by tests/algorithms/golden.py.

One ``.npz`` per (algorithm, reference): ``meta`` (a JSON string: the reference, its version or
commit, the command that recorded it, the reference's hyperparameters the step used), ``in/<name>``
the step's inputs (the batch, the episode cost fed to the multiplier), ``before/<param>`` the
weights the step started from and ``out/<name>`` what the reference computed (losses, gradients
after the clip, the parameters and the multiplier after the step), in float64."""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

import numpy as np

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
