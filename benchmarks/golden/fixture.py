"""The golden-step fixture format, shared by the recording scripts (run in a reference's own venv:
numpy and torch only here, nothing of lac_rllib) and read by tests/algorithms/golden.py.

One ``.npz`` per (algorithm, reference): ``meta`` (a JSON string: the reference, its version or
commit, the command that recorded it, the reference's hyperparameters the step used), ``in/<name>``
the step's inputs (the batch, the episode cost fed to the multiplier), ``before/<param>`` the
weights the step started from and ``out/<name>`` what the reference computed (losses, gradients
after the clip, the parameters and the multiplier after the step), in float64. The meta also
names the recording's Python and CPU (:func:`recording_cpu`): recorded again on the same machine a
fixture has the same arrays bit for bit; on another CPU its float64 products may round otherwise
(ATen's and MKL's kernels follow the CPU's vector instructions), and the arrays agree to ~1e-12."""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

#: Where the fixtures live: the tests read them from there.
FIXTURES = Path(__file__).resolve().parents[2] / "tests" / "fixtures" / "golden"
#: Keys every fixture's meta must carry; the loader refuses a fixture without them.
REQUIRED_META = ("reference", "reference_version", "algorithm", "command")
#: The vector instructions that decide which float kernels ATen and MKL run (lscpu's flag names).
SIMD_FLAGS = ("sse4_2", "avx", "fma", "avx2", "avx512f", "avx512dq", "avx512bw", "avx512vl", "avx512_vnni",
              "avx512_bf16", "amx_tile", "amx_bf16")


def save(path: Path, meta: dict, inputs: dict, before: dict, outputs: dict) -> Path:
    missing = [k for k in REQUIRED_META if not meta.get(k)]
    if missing:
        raise ValueError(f"fixture meta lacks {missing}")
    meta = {**meta, "python": platform.python_version(), "cpu": recording_cpu()}
    arrays = {"meta": np.array(json.dumps(meta, sort_keys=True))}
    for prefix, group in (("in", inputs), ("before", before), ("out", outputs)):
        for name, value in group.items():
            arrays[f"{prefix}/{name}"] = _array(value)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB, {len(arrays) - 1} arrays)", file=sys.stderr)
    return path


def recording_cpu() -> dict:
    """The CPU that recorded: lscpu's model name, which of ``SIMD_FLAGS`` it has, and, where torch
    is loaded, ATen's CPU capability (the kernels it dispatched to)."""
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True,
                             env={**os.environ, "LC_ALL": "C"}).stdout
    except (OSError, subprocess.CalledProcessError):
        out = Path("/proc/cpuinfo").read_text(encoding="utf-8") if Path("/proc/cpuinfo").exists() else ""
    fields = {}
    for line in out.splitlines():
        key, _, value = line.partition(":")
        fields.setdefault(key.strip().lower(), value.strip())
    flags = set(fields.get("flags", "").split())
    cpu = {"model_name": fields.get("model name") or platform.processor() or platform.machine(),
           "simd_flags": [f for f in SIMD_FLAGS if f in flags]}
    torch = sys.modules.get("torch")
    if torch is not None and hasattr(torch.backends, "cpu"):
        cpu["aten_capability"] = torch.backends.cpu.get_cpu_capability()
    return cpu


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
