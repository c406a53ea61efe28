"""The code at another git revision beside today's, timed in turn: the machinery of ``--against REV``
in ``update_step.py`` and ``iteration.py``.

``git archive`` unpacks REV outside the work tree (no worktree bookkeeping); a benchmark then runs
two children of its own script in a serving mode, one importing REV's ``lac_rllib`` and one today's.
Each child builds what it times, announces where its ``lac_rllib`` lives (checked here: REV's
child must not have imported this checkout's, nor today's REV's), then answers one JSON line per
request line the parent writes. The parent asks the two in turn, so that both see the same machine
load; OpenMP is held to one thread in both.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def unpack(rev: str, into: Path) -> str:
    """REV's tree under ``into``; returns its short hash. A revision that is not a commit of this
    repository is refused in one line (ValueError), before anything starts."""
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--short", f"{rev}^{{commit}}"],
                            capture_output=True, text=True)
    if commit.returncode != 0:
        raise ValueError(f"--against {rev!r}: not a commit of this repository ({commit.stderr.strip()})")
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit.stdout.strip()], capture_output=True,
                             check=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return commit.stdout.strip()


@contextlib.contextmanager
def unpacked(rev: str):
    """(short hash, tree) of REV, unpacked into a temporary directory for the ``with`` block."""
    with tempfile.TemporaryDirectory(prefix="against-") as tmp:
        yield unpack(rev, Path(tmp)), Path(tmp)


def _spawn(tree: Path | None, script: str, args: list[str]) -> subprocess.Popen:
    """``script args`` importing ``lac_rllib`` from ``tree`` (None: today's, this checkout's)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    if tree is not None:  # ahead of the editable install, whose finder comes after sys.path
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
    return subprocess.Popen([sys.executable, script, *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=env, cwd=tree or ROOT)


def _reply(child: subprocess.Popen, what: str) -> dict:
    line = child.stdout.readline()
    if not line:
        raise RuntimeError(f"the {what} child exited ({child.wait()}) before answering: see its stderr above")
    return json.loads(line)


@contextlib.contextmanager
def pair(short: str, tree: Path, script: str, args: list[str]):
    """The two serving children of ``script args``, keyed ``short`` (REV's) and ``"today"``, once
    each has announced its package (checked); closed after the ``with`` block."""
    children = {short: _spawn(tree, script, args), "today": _spawn(None, script, args)}
    try:
        where = {k: _reply(c, k)["package"] for k, c in children.items()}
        if not where[short].startswith(str(tree)) or where["today"].startswith(str(tree)):
            raise RuntimeError(f"the children imported the wrong lac_rllib: {where}")
        yield children
    finally:
        for c in children.values():
            c.stdin.close()
            c.wait()


def ask(children: dict, request: str = "time") -> dict[str, dict]:
    """One request to each child in turn; their replies by key."""
    replies = {}
    for k, c in children.items():
        c.stdin.write(request + "\n")
        c.stdin.flush()
        replies[k] = _reply(c, k)
    return replies


def announce() -> None:
    """The child's first line: where the ``lac_rllib`` it imported lives."""
    import lac_rllib

    print(json.dumps({"package": str(Path(lac_rllib.__file__).resolve().parent)}), flush=True)


def requests():
    """The parent's requests, one per line, until it closes the pipe."""
    yield from sys.stdin
