"""Config fields declared once: a dataclass field with its default, the values it accepts and a
docstring below it. Every algorithm's params class is written this way (``LACParams``,
``SafeTaskParams``); from that one declaration come the check of a value as it is set (so bad
input fails before Ray starts), the ``--set FIELD=VALUE`` parser, ``lac-train --help`` and
docs/config.md.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import math
from typing import Any, Callable

from lac_rllib.errors import excerpt


@dataclasses.dataclass(frozen=True)
class Accepted:
    """The values a field accepts: ``test`` checks a value, ``text`` says it (in the error for a
    bad value, docs/config.md and ``lac-train --help``)."""

    text: str
    test: Callable[[Any], bool]


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_real(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def one_of(choices: tuple[str, ...]) -> Accepted:
    return Accepted(" | ".join(map(str, choices)), lambda v: isinstance(v, str) and v in choices)


def or_none(accepted: Accepted) -> Accepted:
    return Accepted(f"None or {accepted.text}", lambda v: v is None or accepted.test(v))


# The accepted values several fields share.
INT_GE_0 = Accepted("an integer >= 0", lambda v: _is_int(v) and v >= 0)
INT_GE_1 = Accepted("an integer >= 1", lambda v: _is_int(v) and v >= 1)
FINITE = Accepted("a finite number", _is_real)
POSITIVE = Accepted("a finite number > 0", lambda v: _is_real(v) and v > 0)
NON_NEGATIVE = Accepted("a finite number >= 0", lambda v: _is_real(v) and v >= 0)
FRACTION = Accepted("a number in (0, 1]", lambda v: _is_real(v) and 0 < v <= 1)
BOOL = Accepted("True | False", lambda v: isinstance(v, bool))
LIMITS = Accepted("a non-empty mapping of constraint names to finite numbers >= 0",
                  lambda v: isinstance(v, dict) and len(v) >= 1
                  and all(isinstance(k, str) and _is_real(b) and b >= 0 for k, b in v.items()))
NAME = Accepted("a name (letters, digits, _ . -)", lambda v: isinstance(v, str) and bool(v)
                and len(v) <= 60 and all(ch.isalnum() or ch in "_.-" for ch in v))
LAYERS = Accepted("a non-empty sequence of integers >= 1",
                  lambda v: isinstance(v, (tuple, list)) and len(v) >= 1 and all(_is_int(h) and h >= 1 for h in v))


def param(default: Any, *, accepts: Accepted) -> Any:
    """A field of a params dataclass: its default and the values it accepts."""
    return dataclasses.field(default=default, metadata={"accepts": accepts})


def accepted_values(params_cls) -> dict[str, Accepted]:
    """Each field's accepted values, as its ``param(..., accepts=...)`` declares them."""
    return {f.name: f.metadata["accepts"] for f in dataclasses.fields(params_cls)}


def field_docs(params_cls) -> dict[str, str]:
    """Each field's docstring, read from the source of ``params_cls`` and its bases (the single
    place each is written)."""
    docs: dict[str, str] = {}
    for cls in reversed([c for c in params_cls.__mro__ if dataclasses.is_dataclass(c)]):
        body = ast.parse(inspect.getsource(cls)).body[0].body
        for node, nxt in zip(body, body[1:]):
            if isinstance(node, ast.AnnAssign) and isinstance(nxt, ast.Expr):
                docs[node.target.id] = " ".join(str(nxt.value.value).split())
    return docs


def check_value(ranges: dict[str, Accepted], name: str, value: Any, *, what: str) -> None:
    """Raise a ValueError naming the field, the value and the accepted values if ``value`` is bad."""
    accepted = ranges.get(name)
    if accepted is not None and not accepted.test(value):
        raise ValueError(f"{what} config field {name}={excerpt(value)} is invalid; accepted: {accepted.text}")




def parse_sets(pairs: list[str], names, *, what: str) -> dict:
    """``["temperature=1e-4", "actor_hidden=(64, 64)"]`` → dict; an unknown name lists ``names``."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        name = name.strip()
        if not sep:
            raise ValueError(f"--set {pair!r}: expected field=value")
        if name not in names:
            raise ValueError(f"--set: unknown {what} config field {name!r}; accepted: {', '.join(sorted(names))}")
        try:
            out[name] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[name] = raw  # plain strings such as informative / next
    return out


class FieldSet:
    """The fields of one algorithm's params dataclass, with what each accepts: the check, the
    ``--set`` parser and the docstrings every algorithm's config module exposes (``FIELDS``)."""

    def __init__(self, params_cls, what: str):
        self.params_cls, self.what = params_cls, what
        self.ranges: dict[str, Accepted] = accepted_values(params_cls)
        self.names = frozenset(self.ranges)
        self.defaults = {f.name: f.default for f in dataclasses.fields(params_cls)}

    def docs(self) -> dict[str, str]:
        return field_docs(self.params_cls)

    def check(self, name: str, value: Any) -> None:
        """Raise a ValueError naming the field, the value and the accepted values if ``value`` is bad."""
        check_value(self.ranges, name, value, what=self.what)

    def parse_sets(self, pairs: list[str]) -> dict:
        return parse_sets(pairs, self.names, what=self.what)
