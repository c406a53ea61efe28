"""The code passes the linter configured in pyproject.toml ([tool.ruff]): part of the test command."""

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    assert ruff, "ruff is not installed: pip install -e '.[test]'"
    proc = subprocess.run([ruff, "check", "--no-cache", str(REPO)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]


def test_no_backslash_line_continuations():
    """Continuations in the package and benchmarks go in parentheses, as everywhere else (a backslash breaks on a
    trailing space and reads as an unfinished line)."""
    import io
    import tokenize

    found = []
    for path in sorted(p for d in ("lac_rllib", "sweeps", "benchmarks") for p in (REPO / d).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        in_string = set()
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.STRING:
                in_string.update(range(tok.start[0], tok.end[0]))  # a string's own lines but its last
        found += [f"{path.relative_to(REPO)}:{i}" for i, line in enumerate(text.splitlines(), 1)
                  if line.rstrip().endswith("\\") and i not in in_string]
    assert not found, found
