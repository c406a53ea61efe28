"""How an error line quotes a bad value: a short, cut ``repr`` (:func:`excerpt`); and how a step
that runs a user's code says so first (:func:`announce`).

Values reach the checks from sweep files, flags and users' envs, and may be huge (an alias tree, a
list of a million numbers, an exception's text): an error line never prints the whole of one.
Plain Python, importable from every layer (the tasks' registry included).
"""

from __future__ import annotations

import reprlib
import sys
from typing import Any

#: The start of every line :func:`announce` writes (a CLI's own errors start with its name).
ANNOUNCE = "lac-rllib: "

_REPR = reprlib.Repr()  # Python 3.11's takes no keywords
_REPR.maxstring, _REPR.maxother, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxlevel = 40, 40, 4, 4, 3, 2


def excerpt(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to at most ``limit`` characters (containers to their first items)."""
    text = _REPR.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def cut(text: str, limit: int = 160) -> str:
    """``text`` (an exception's message, say) on one line, cut to at most ``limit`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def announce(what: str) -> None:
    """Say on stderr, before it runs, which user's code a step runs (importing a user's algorithm,
    building and stepping a user's env), so a slow or hanging one is never a silent command."""
    print(ANNOUNCE + what, file=sys.stderr, flush=True)
