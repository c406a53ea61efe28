"""A sweep's trials as configurations, and how the reports write them: the key columns of a
configuration, the trials prepared (failed ones marked), the sort order of swept values and the
display of values, numbers and intervals. Every report module (report, safety, importance,
frontier, chain_health, confirm) imports these from here, none from another report module.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import EPISODE_COST, EPISODE_RETURN

#: The columns that name a configuration (its rows are its seeds).
KEYS = ["group", "param", "value", "task", "config"]


def is_na(v) -> bool:
    return v is None or (pd.api.types.is_scalar(v) and bool(pd.isna(v)))


def text_column(df: pd.DataFrame, col: str) -> pd.Series | str:
    """``df[col]`` as text, a missing cell as "" ("" for a missing column). Cast to object first:
    a column with no value at all is float NaN, and pandas 3 refuses filling one with a string."""
    return df[col].astype(object).fillna("").astype(str) if col in df else ""


def value_key(v) -> tuple:
    """Sort key: numeric values first (numerically), then strings, then missing."""
    if is_na(v):
        return (2, 0.0, "")
    try:
        return (0, float(v), "")
    except (TypeError, ValueError):
        return (1, 0.0, str(v))


def fmt_value(v) -> str:
    """Display form of a swept value: 30.0 -> "30", missing -> "–"."""
    if is_na(v):
        return "–"
    return str(int(v)) if isinstance(v, (float, np.floating)) and float(v).is_integer() else str(v)


def metric_name(text: str) -> str:
    """``text`` (a task, a configuration) as a part of an MLflow metric's name: MLflow refuses a name
    with other characters than letters, digits and ``_ - . /`` and spaces (a split task's ``@``)."""
    return re.sub(r"[^\w\-./ ]", "_", str(text))


def fmt_num(x) -> str:
    return "–" if is_na(x) else f"{float(x):.2f}"


def prepared(trials: pd.DataFrame) -> tuple[pd.DataFrame, pd.Series]:
    """Copy of ``trials`` with a clean ``param`` column, and the boolean mask of failed trials."""
    df = trials.copy()
    df["param"] = text_column(df, "param")
    # "config": the configuration without its seed (lac.config; a search's samples share group,
    # param and value); "default": the trial runs LAC's defaults, the baseline of the comparisons.
    df["config"] = text_column(df, "config")
    df["default"] = df["default"].fillna(False).astype(bool) if "default" in df else False
    failed = df["status"].astype(str).eq("ERROR")
    for col in (EPISODE_RETURN, EPISODE_COST):
        failed |= pd.to_numeric(df[col], errors="coerce").isna()
    return df, failed


def ci(point, lo, hi) -> str:
    """"2.19 [1.10, 3.05]"; the interval shows "–" when undefined (fewer than 2 seeds)."""
    if is_na(point):
        return "–"
    return f"{fmt_num(point)} [{fmt_num(lo)}, {fmt_num(hi)}]" if not is_na(lo) else f"{fmt_num(point)} [–]"
