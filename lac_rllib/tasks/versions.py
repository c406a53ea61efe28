"""Versions of the simulation stack and the CPU's features, for run metadata.

numpy and mujoco versions change trajectories, so every run records them (docs/dependencies.md,
"Versions that change results"). Read from package metadata, so nothing heavy is imported.
"""

from __future__ import annotations

import platform
from importlib import metadata

_PACKAGES = ("numpy", "mujoco", "gymnasium", "safety_gymnasium")


def runtime_versions() -> dict[str, str | None]:
    """``{"python", "numpy", "mujoco", "gymnasium", "safety_gymnasium"}`` → version (None if absent)."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name.replace("_", "-"))
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


#: CPU flags (Linux /proc/cpuinfo) of native bfloat16 matmuls: AVX512-BF16 or AMX.
BF16_FLAGS = ("avx512_bf16", "amx_bf16")


def cpu_flags() -> set[str]:
    """This CPU's feature flags as Linux reports them (empty where /proc/cpuinfo is not there)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()
