"""The registry of tuned configurations: ``tuned/<task>/<algo>.yaml``, one confirmed winner each.

A tuned comparison (sweeps/tuned.py) writes each algorithm's confirmed winner with its evidence: the
configuration (the searched fields' values), the budget, the limit, the seeds of the search and of the
confirmation, the fresh-seed scores with intervals, the sweeps' MLflow runs, the commit and the env
fingerprint (lac_rllib/tasks/fingerprint.py). ``preset: tuned`` in a sweep file starts every trial
from its task's, algorithm's and budget's entry; an entry is read as untrusted input (bounded YAML, a
pydantic model with no unknown keys, every field checked against its algorithm's declaration) and is
refused in one line, before Ray starts, where it is missing, malformed, or of another environment.
``lac-sweep registry`` lists the entries.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

#: The repository's registry (entries ship with the code: tuned/ beside sweeps/).
DEFAULT_REGISTRY = Path(__file__).resolve().parents[1] / "tuned"


class Scores(BaseModel):
    """A configuration's scores on seeds: mean [CI] of return and cost, and P(feasible)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    n_seeds: int = Field(ge=0)
    return_mean: float | None
    return_ci: tuple[float | None, float | None]
    cost_mean: float | None
    cost_ci: tuple[float | None, float | None]
    p_feasible: float | None = Field(None, ge=0, le=1)


class Entry(BaseModel):
    """One tuned configuration and its evidence."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    task: str = Field(min_length=1, max_length=200)
    """The task id it was tuned on."""
    algo: str = Field(min_length=1, max_length=200)
    """The algorithm."""
    budget: str | int
    """The sweep's budget (a name or env steps) it was tuned and confirmed at."""
    timesteps: int = Field(ge=1)
    """Env steps per trial."""
    cost_limit: float = Field(ge=0)
    """The limit it was judged at."""
    config: dict[str, Any]
    """The searched fields' values: what ``preset: tuned`` sets on top of the algorithm's defaults."""
    search_seeds: tuple[int, ...]
    """The seeds the search trained each configuration with."""
    fresh_seeds: tuple[int, ...]
    """The confirmation's seeds, none of which the search saw."""
    fresh: Scores
    """Its scores on the fresh seeds."""
    default_fresh: Scores
    """The algorithm's default on the same fresh seeds."""
    search: dict[str, Any]
    """Its figures on the search's seeds (the winner's curse is their difference to ``fresh``)."""
    search_feasible: bool = True
    """Whether its search had a configuration feasible on average; where not, this one is the least
    costly (sweeps/tuned.py ``pick_winners``), written so that ``preset: tuned`` is not read as a safe choice."""
    mlflow: dict[str, str]
    """The tracking URI and the parent runs: the search's and the confirmation's."""
    commit: str
    """The code's commit."""
    fingerprint: dict[str, Any]
    """The env fingerprint its runs had (lac_rllib/tasks/fingerprint.py)."""
    fingerprint_id: str
    """Its id."""


def entry_path(registry: Path, task: str, algo: str) -> Path:
    return Path(registry) / task / f"{algo}.yaml"


def _scores(fig: dict) -> dict:
    ret, cost = fig["return"], fig["cost"]
    return {"n_seeds": fig["n_seeds"], "return_mean": _f(ret[0]), "return_ci": (_f(ret[1]), _f(ret[2])),
            "cost_mean": _f(cost[0]), "cost_ci": (_f(cost[1]), _f(cost[2])), "p_feasible": _f(fig["p_feasible"])}


def _f(x):
    return None if x is None or x != x else float(x)


def write_entries(tp, comp: dict, winners: dict, confirm_parent: str, searches: dict, trials) -> list[Path]:
    """Each algorithm's confirmed winner written to ``tp.registry`` (an entry replaced by a newer one)."""
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id
    from sweeps import spaces
    from sweeps.record import git_commit, parent_run_id

    written = []
    fresh = tuple(sorted(int(s) for s in trials["seed"].unique()))
    for algo, v in comp["algorithms"].items():
        plan = searches[algo]
        fields = winners[algo][0]["fields"]
        params = spaces.trial_params(tp.task, tp.sweep.budget, {**plan.sets}, {"algo": algo, **fields})
        fp = fingerprint(tp.task, params)
        entry = Entry(task=tp.task, algo=algo, budget=tp.sweep.budget, timesteps=plan.timesteps,
                      cost_limit=v["tuned"]["limit"], config=json.loads(json.dumps(fields, default=str)),
                      search_seeds=plan.seeds, fresh_seeds=fresh, fresh=_scores(v["tuned"]),
                      default_fresh=_scores(v["default"]), search=winners[algo][0]["search"],
                      search_feasible=winners[algo][0]["feasible"],
                      mlflow={"tracking_uri": plan.tracking_uri,
                              "search_run": parent_run_id(Path(plan.storage) / plan.name),
                              "confirmation_run": confirm_parent},
                      commit=git_commit(), fingerprint=fp, fingerprint_id=fingerprint_id(fp))
        path = entry_path(tp.registry, tp.task, algo)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(yaml.safe_dump(_plain(entry.model_dump()), sort_keys=False, width=110))
        written.append(path)
    return written


def _plain(v):
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def read_entry(path: Path) -> Entry:
    """An entry read as untrusted input: bounded YAML, the schema, every field of ``config`` against
    its algorithm's declaration; a ValueError of one line naming the file and what is wrong."""
    from sweeps.bounded_yaml import YamlRefused, read_text
    from sweeps.bounded_yaml import read as read_yaml
    from sweeps.sweep_file import FieldError, NumbersLoader, check_field

    try:
        data, _ = read_yaml(read_text(path), NumbersLoader)
        entry = Entry.model_validate(data)
    except YamlRefused as e:
        raise ValueError(f"{path}: {e.message}") from None
    except ValidationError as e:
        err = e.errors()[0]
        raise ValueError(f"{path}: {'.'.join(map(str, err['loc'])) or 'entry'}: {err['msg']}; accepted: an entry "
                         "as sweeps/tuned_registry.py writes it") from None
    from lac_rllib.tasks.fingerprint import fingerprint_id

    if fingerprint_id(entry.fingerprint) != entry.fingerprint_id:
        raise ValueError(f"{path}: fingerprint_id {entry.fingerprint_id} is not its fingerprint's "
                         f"({fingerprint_id(entry.fingerprint)}): the entry was edited; refused")
    try:
        from lac_rllib.algorithms.registry import check_algo

        check_algo(entry.algo)
        for name, value in entry.config.items():
            check_field(name, value, (entry.algo,), ("config", name))
    except FieldError as e:
        raise ValueError(f"{path}: {'.'.join(map(str, e.loc))}: {e.message}") from None
    return entry


def tuned_fields(registry: Path, task: str, algo: str, budget, sets: dict) -> dict:
    """The fields ``preset: tuned`` sets for a trial of ``algo`` on ``task`` at ``budget``: its entry's
    configuration, refused where there is none for that budget or its env fingerprint differs from
    the one such a trial has here."""
    from lac_rllib.tasks.fingerprint import differences, fingerprint, fingerprint_id
    from sweeps import spaces

    path = entry_path(registry, task, algo)
    if not path.is_file():
        have = sorted(str(p.relative_to(registry)) for p in Path(registry).glob("**/*.yaml")) if Path(
            registry).is_dir() else []
        raise ValueError(f"preset: tuned: the registry {registry} has no entry for {algo} on {task}; accepted: "
                         f"{', '.join(have) or 'none yet'} (a tuned comparison writes them: tune: in a sweep file)")
    entry = read_entry(path)
    if entry.task != task or entry.algo != algo:
        raise ValueError(f"{path}: an entry of {entry.algo} on {entry.task} filed as {algo} on {task}; refused")
    if str(entry.budget) != str(budget):
        raise ValueError(f"preset: tuned: {path} was tuned at budget {entry.budget}, this sweep's is {budget}; "
                         f"accepted: budget {entry.budget}, or tune at {budget}")
    params = spaces.trial_params(task, budget, sets, {"algo": algo, **entry.config})
    now = fingerprint(task, params)
    if fingerprint_id(now) != entry.fingerprint_id:  # read_entry checked the id is its fingerprint's
        raise ValueError(f"preset: tuned: {path} was tuned in another environment: "
                         f"{differences(entry.fingerprint, now)}; accepted: an entry tuned in this one")
    return dict(entry.config)


def listing(registry: Path) -> str:
    """``lac-sweep registry``: one line per entry."""
    paths = sorted(Path(registry).glob("**/*.yaml")) if Path(registry).is_dir() else []
    if not paths:
        return f"no tuned configurations in {registry}"
    lines = [f"tuned configurations in {registry}:"]
    for p in paths:
        try:
            e = read_entry(p)
        except ValueError as err:
            lines.append(f"  {p.relative_to(registry)}: refused: {err}")
            continue
        f = e.fresh
        lines.append(f"  {e.task} {e.algo} @ {e.budget} (limit {e.cost_limit:g}): "
                     f"{', '.join(f'{k}={v}' for k, v in e.config.items())}; fresh seeds {len(e.fresh_seeds)}: "
                     f"return {f.return_mean:.3g}, cost {f.cost_mean:.3g} (default {e.default_fresh.return_mean:.3g}, "
                     f"{e.default_fresh.cost_mean:.3g}); env {e.fingerprint_id}"
                     + ("" if e.search_feasible else "; its search had nothing feasible: the least costly"))
    return "\n".join(lines)
