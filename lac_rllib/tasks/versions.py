"""Versions of the simulation stack, for run metadata.

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
