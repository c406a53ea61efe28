"""A benchmark script imported by its path: benchmarks/ is a folder of scripts, not a package."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_benchmark(script: str, name: str | None = None):
    """The script ``script`` of benchmarks/ as a module (named ``name``, default ``<script>_benchmark``)."""
    spec = importlib.util.spec_from_file_location(name or f"{script}_benchmark", ROOT / "benchmarks" / f"{script}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
