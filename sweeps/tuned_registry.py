"""The registry of tuned configurations: ``tuned/<task>/<algo>/<budget>-b<limit>-<env>.yaml``, one
entry per algorithm and what it was tuned under.

A tuned comparison (sweeps/tuned.py) writes each algorithm's **verdict** with its evidence:

- ``improved``: the tuned configuration beat the default on the confirmation's fresh seeds by the
  paired test (sweeps/reports/tuned.py ``improved``: it is feasible and the paired gap's interval
  lies wholly above 0). ``config`` is that configuration: what ``preset: tuned`` sets.
- ``default-stands``: it did not. ``config`` is empty and ``candidate`` holds the configuration that
  was tried; ``preset: tuned`` runs the algorithm's default and says so in one line.

Beside it: the budget, the limit and the constraints it was judged under, the search (searcher,
samples, how many came from the searcher's random start, the declared search space as data), the
seeds of the search and of the confirmation, the fresh-seed scores of both with their intervals and
per seed, the paired gap, the interval methods (sweeps/reports/verdicts.py ``METHODS``), the sweeps'
MLflow runs, the commit the search ran at (its MLflow parent run's ``git_commit``; where that is not
found, the commit when the entry was written, ``commit_source`` says which) and the env fingerprint
(lac_rllib/tasks/fingerprint.py).

**No entry is lost.** An entry is kept per what it was tuned under, its key ``BUDGET-bLIMIT-ENV``
(the budget, the limit, i.e. the one summed cost's constraint, and the fingerprint's id): a
comparison at another budget, limit or environment writes beside it. One with the same key replaces
it, said in the output, the old entry moved to ``history/`` beside it (named by its date or commit).
A ``smoke`` comparison writes into a registry only when ``--registry`` names one: otherwise into
``registry/`` in its confirmation's directory, said where.

``preset: tuned`` starts every trial from the entry of its task and algorithm at the sweep's budget,
at the trial's limit (or the sweep file's ``tuned_limit``) and in the environment the trial has
(checked per trial, after its group's and grid's fields). An entry is read as untrusted input
(bounded YAML, a pydantic model with no unknown keys, every field checked against its algorithm's
declaration) and is refused in one line, before Ray starts, where it is missing, malformed, or of
another budget, limit or environment. ``lac-sweep registry`` lists the entries.

Entries written before the verdict and the search's record (the shipped ones, and the earlier layout
``tuned/<task>/<algo>.yaml``, still read) lack those fields: None, listed as "unknown"; an entry
without a verdict is applied as it was.
"""

from __future__ import annotations

import datetime
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

#: The repository's registry (entries ship with the code: tuned/ beside sweeps/).
DEFAULT_REGISTRY = Path(__file__).resolve().parents[1] / "tuned"
#: The verdicts an entry carries.
IMPROVED, DEFAULT_STANDS = "improved", "default-stands"
#: Where a replaced entry is kept, beside the entries of its algorithm.
HISTORY = "history"
#: The budget whose comparisons write into a registry only when ``--registry`` names one.
SMOKE = "smoke"
#: Where ``commit`` came from.
COMMIT_FROM_SEARCH = "the search's MLflow parent run (param git_commit)"
COMMIT_AT_WRITE = "git HEAD when the entry was written: the search's MLflow parent run gave no commit"


class Scores(BaseModel):
    """A configuration's scores on seeds: mean [CI] of return and cost, and P(feasible)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    n_seeds: int = Field(ge=0)
    return_mean: float | None
    return_ci: tuple[float | None, float | None]
    cost_mean: float | None
    cost_ci: tuple[float | None, float | None]
    p_feasible: float | None = Field(None, ge=0, le=1)
    p_feasible_ci: tuple[float | None, float | None] | None = None
    """P(feasible)'s interval (``intervals.proportion``); None: not recorded."""


class Entry(BaseModel):
    """One algorithm's tuned configuration (or the verdict that its default stands) and its evidence.
    The fields after ``fingerprint_id`` came later: None where an entry predates them (unknown)."""

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
    """What ``preset: tuned`` sets on top of the algorithm's defaults: the searched fields' values; empty
    (or ignored) where the verdict is that the default stands."""
    search_seeds: tuple[int, ...]
    """The seeds the search trained each configuration with."""
    fresh_seeds: tuple[int, ...]
    """The confirmation's seeds (their integers are not the search's)."""
    fresh: Scores
    """The tuned configuration's scores on the fresh seeds."""
    default_fresh: Scores
    """The algorithm's default on the same fresh seeds."""
    search: dict[str, Any]
    """Its figures on the search's seeds (the winner's curse is their difference to ``fresh``)."""
    search_feasible: bool = True
    """Whether its search had a feasible configuration; where not, this one is the least costly
    (sweeps/tuned.py ``pick_winners``), written so that ``preset: tuned`` is not read as a safe choice."""
    mlflow: dict[str, str]
    """The tracking URI and the parent runs: the search's and the confirmation's."""
    commit: str
    """The code's commit (``commit_source``: the search's or the writer's)."""
    fingerprint: dict[str, Any]
    """The env fingerprint its runs had (lac_rllib/tasks/fingerprint.py)."""
    fingerprint_id: str
    """Its id."""
    verdict: Literal["improved", "default-stands"] | None = None
    """``improved``: the paired test on the fresh seeds showed the tuned configuration better than the
    default, ``config`` is it; ``default-stands``: it did not, ``preset: tuned`` runs the default."""
    candidate: dict[str, Any] | None = None
    """Where the default stands: the tuned configuration that was confirmed and not shown better."""
    constraints: dict[str, float] | None = None
    """What it was constrained by: ``{cost: LIMIT}`` (the one summed cost), or each constraint's limit
    (``{hazards: 10, vases: 5}``, a run with ``constraints``: docs/constraints.md; ``cost_limit`` is
    then 0, the joint rule's)."""
    searcher: str | None = None
    """The search's sampler."""
    num_samples: int | None = Field(None, ge=1)
    """Configurations the search sampled."""
    random_start: int | None = Field(None, ge=0)
    """How many of them the searcher drew in its random start (sweeps/search.py)."""
    search_space: dict[str, Any] | None = None
    """The algorithm's declared distributions the search sampled, as data."""
    by_seed: dict[Literal["tuned", "default"], dict[int, float | None]] | None = None
    """Return on each fresh seed: the tuned configuration's and the default's."""
    gap: tuple[float | None, float | None, float | None] | None = None
    """Tuned − default in return, paired by seed: (mean, low, high) (``intervals.paired``)."""
    pairs: int | None = Field(None, ge=0)
    """The seeds both finished: what the paired gap rests on."""
    p_improvement: float | None = Field(None, ge=0, le=1)
    """P(a tuned seed beats a default one)."""
    intervals: dict[str, str] | None = None
    """How each interval was computed (sweeps/reports/verdicts.py ``METHODS``): mean, paired, proportion."""
    commit_source: str | None = None
    """Where ``commit`` came from: the search's parent run, or the writer's HEAD."""
    written: str | None = None
    """When the entry was written (UTC, ISO 8601)."""
    schedule: tuple[dict[str, Any], ...] | None = None
    """A population-based search's winner (``searcher: pbt``): the schedule its fields followed,
    ``[{at: env steps, set: {field: value}}, ...]``: what ``preset: tuned`` replays where improved
    (the fields its first step sets are ``config``'s then); where the default stands, the schedule tried."""


def _num(x: float) -> str:
    """A limit as a file name's part: ``2``, ``0.5``, exact (``repr`` where ``g`` would round)."""
    s = f"{float(x):g}"
    return s if float(s) == float(x) else repr(float(x))


def entry_key(budget, cost_limit: float, fingerprint_id: str, constraints: dict | None = None) -> str:
    """What an entry is kept by: its budget, its limit (one summed cost's) or each constraint's, and its env."""
    if named_limits(constraints):
        limits = "-".join(f"{n}{_num(b)}" for n, b in sorted(constraints.items()))
        return f"{budget}-{limits}-{fingerprint_id}"
    return f"{budget}-b{_num(cost_limit)}-{fingerprint_id}"


def named_limits(constraints: dict | None) -> dict[str, float]:
    """An entry's or a trial's limit per constraint (its ``constraints``), {} for one on the summed cost."""
    if not constraints or set(constraints) == {"cost"}:
        return {}
    return {str(n): float(b) for n, b in constraints.items()}


def key_of(entry: Entry) -> str:
    return entry_key(entry.budget, entry.cost_limit, entry.fingerprint_id, entry.constraints)


def entry_path(registry: Path, task: str, algo: str, key: str) -> Path:
    return Path(registry) / task / algo / f"{key}.yaml"


def legacy_path(registry: Path, task: str, algo: str) -> Path:
    """Where entries were written before they were kept by key (one per task and algorithm)."""
    return Path(registry) / task / f"{algo}.yaml"


def entry_paths(registry: Path, task: str, algo: str) -> list[Path]:
    """The current entries of ``algo`` on ``task`` (not those in ``history/``), the earlier layout's last."""
    folder = Path(registry) / task / algo
    paths = sorted(folder.glob("*.yaml")) if folder.is_dir() else []
    legacy = legacy_path(registry, task, algo)
    return paths + ([legacy] if legacy.is_file() else [])


def applied(entry: Entry) -> dict:
    """The fields ``preset: tuned`` sets from ``entry``: none where the default stands."""
    return {} if entry.verdict == DEFAULT_STANDS else dict(entry.config)


def applied_schedule(entry: Entry) -> list | None:
    """The schedule ``preset: tuned`` replays from ``entry`` (a PBT winner's, improved), as
    [[env steps, fields], ...] (sweeps/spaces.py TrialSpec.schedule); None: fixed fields."""
    if entry.verdict == DEFAULT_STANDS or not entry.schedule:
        return None
    return [[int(step["at"]), dict(step["set"])] for step in entry.schedule]


def _scores(fig: dict) -> dict:
    ret, cost = fig["return"], fig["cost"]
    p_ci = fig.get("p_feasible_ci")
    return {"n_seeds": fig["n_seeds"], "return_mean": _f(ret[0]), "return_ci": (_f(ret[1]), _f(ret[2])),
            "cost_mean": _f(cost[0]), "cost_ci": (_f(cost[1]), _f(cost[2])), "p_feasible": _f(fig["p_feasible"]),
            "p_feasible_ci": None if p_ci is None else (_f(p_ci[1]), _f(p_ci[2]))}


def _f(x):
    return None if x is None or x != x else float(x)


def destination(tp) -> tuple[Path, str | None]:
    """Where a tuned comparison writes its entries, and why there where it is not its registry: a
    ``smoke`` comparison writes into a registry only when ``--registry`` names one."""
    if str(tp.sweep.budget) == SMOKE and not tp.registry_asked:
        from sweeps.followup import confirmation_name

        first = next(iter(tp.searches.values()))
        return (Path(first.storage) / confirmation_name(tp.name) / "registry",
                f"a {SMOKE} budget writes into a registry only when --registry names one")
    return Path(tp.registry), None


def search_commit(tracking_uri: str, run_id: str) -> tuple[str, str]:
    """The commit a search ran at, from its MLflow parent run (``git_commit``), and where it came from;
    where the run is not found or recorded none, this checkout's HEAD (said in the second)."""
    from sweeps.record import git_commit

    commit = None
    db = tracking_uri.removeprefix("sqlite:///") if tracking_uri.startswith("sqlite:///") else None
    if db is None or Path(db).exists():  # a missing sqlite file is not made here
        try:
            from mlflow import MlflowClient

            commit = MlflowClient(tracking_uri).get_run(run_id).data.params.get("git_commit")
        except Exception:  # noqa: BLE001 (an unreachable or pruned store: the fallback, said in the entry)
            commit = None
    if commit and commit != "unknown":
        return commit, COMMIT_FROM_SEARCH
    return git_commit(), COMMIT_AT_WRITE


def _random_start(plan) -> int | None:
    """How many of the search's samples its searcher drew at random (the plan's, else sweeps/search.py's
    rule); None where neither says."""
    if getattr(plan, "random_start", None) is not None:
        return int(plan.random_start)
    if plan.sweep.searcher == "pbt":  # every member's first fields are a random draw
        return int(plan.sweep.pbt.members)
    try:
        from sweeps.search import random_start
    except ImportError:
        return None
    return random_start(plan.sweep.searcher, plan.sweep.num_samples)


def _space(search) -> dict | None:
    if not search:
        return None
    return _plain(json.loads(json.dumps({k: d.model_dump(exclude_none=True) if hasattr(d, "model_dump") else d
                                         for k, d in search.items()}, default=str)))


def write_entries(tp, comp: dict, winners: dict, confirm_parent: str, searches: dict, trials) -> list[Path]:
    """Each algorithm's verdict written (:func:`destination`): its tuned configuration where the paired
    test on the fresh seeds showed it better than the default, else ``default-stands``; an entry of the
    same key is replaced only with the old one kept in ``history/`` (both said)."""
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id
    from sweeps import spaces
    from sweeps.record import parent_run_id
    from sweeps.reports.verdicts import METHODS

    registry, why = destination(tp)
    if why:
        print(f"registry: {why}: the entries go to {registry}", flush=True)
    written = []
    fresh = tuple(sorted(int(s) for s in trials["seed"].unique()))
    now = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
    for algo, v in comp["algorithms"].items():
        plan = searches[algo]
        winner = winners[algo][0]
        schedule = _plain(json.loads(json.dumps(winner.get("schedule"), default=str)))  # a PBT winner's
        fields = _plain(json.loads(json.dumps(winner["fields"] or (schedule or [{}])[0].get("set", {}), default=str)))
        improved = bool(v["improved"])
        config = fields if improved else {}
        params = spaces.trial_params(tp.task, tp.sweep.budget, {**plan.sets}, {"algo": algo, **config})
        fp = fingerprint(tp.task, params)
        limit = float(v["tuned"]["limit"])
        limits = named_limits(params.get("constraints"))  # several constraints: each one's limit
        search_run = parent_run_id(Path(plan.storage) / plan.name)
        commit, source = search_commit(plan.tracking_uri, search_run)
        gap = v.get("gap")
        entry = Entry(task=tp.task, algo=algo, budget=tp.sweep.budget, timesteps=plan.timesteps,
                      cost_limit=limit, config=config, search_seeds=plan.seeds, fresh_seeds=fresh,
                      fresh=_scores(v["tuned"]), default_fresh=_scores(v["default"]), search=winner["search"],
                      search_feasible=winner["feasible"],
                      mlflow={"tracking_uri": plan.tracking_uri, "search_run": search_run,
                              "confirmation_run": confirm_parent},
                      commit=commit, fingerprint=fp, fingerprint_id=fingerprint_id(fp),
                      verdict=IMPROVED if improved else DEFAULT_STANDS, candidate=None if improved else fields,
                      constraints=limits or {"cost": limit}, searcher=plan.sweep.searcher,
                      num_samples=plan.sweep.num_samples or (plan.sweep.pbt.members if plan.sweep.pbt else None),
                      random_start=_random_start(plan), search_space=_space(plan.sweep.search),
                      by_seed={"tuned": _by_seed(v["tuned"]), "default": _by_seed(v["default"])},
                      gap=None if gap is None else tuple(_f(x) for x in gap), pairs=v.get("pairs"),
                      p_improvement=_f(v.get("p_improvement")),
                      intervals={k: METHODS[k] for k in ("mean", "paired", "proportion")},
                      commit_source=source, written=now, schedule=schedule)
        key = key_of(entry)
        path = entry_path(registry, tp.task, algo, key)
        text = yaml.safe_dump(_plain(entry.model_dump()), sort_keys=False, width=110, allow_unicode=True)
        _keep_replaced(registry, tp.task, algo, key, path, text)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        if not improved:
            print(f"registry: {algo} on {tp.task}: tuning did not beat the default on the fresh seeds (paired gap "
                  f"{_gap_text(entry.gap)}): {path} says the default stands", flush=True)
        written.append(path)
    return written


def _by_seed(fig: dict) -> dict:
    return {int(s): _f(r) for s, r in sorted(fig.get("by_seed", {}).items())}


def _gap_text(gap) -> str:
    if not gap or gap[0] is None:
        return "unknown"
    return f"{gap[0]:.3g}" + ("" if gap[1] is None else f" [{gap[1]:.3g}, {gap[2]:.3g}]")


def _keep_replaced(registry: Path, task: str, algo: str, key: str, path: Path, text: str) -> None:
    """An entry of the same key as the one about to be written at ``path`` (there, or in the earlier
    layout) moved to ``history/`` and said; one with the same bytes is left as it is."""
    olds = [path] if path.is_file() else []
    legacy = legacy_path(registry, task, algo)
    if legacy.is_file():
        try:
            if key_of(read_entry(legacy)) == key:
                olds.append(legacy)
        except ValueError:
            pass  # unreadable: not the same key as far as anyone can tell; left where it is
    for old in olds:
        if old == path and old.read_text() == text:
            continue
        kept = _history_path(registry, task, algo, key, old)
        kept.parent.mkdir(parents=True, exist_ok=True)
        old.rename(kept)
        print(f"registry: {path} replaces an entry tuned under the same budget, limit and environment ({key}); "
              f"the old entry is kept as {kept}", flush=True)


def _history_path(registry: Path, task: str, algo: str, key: str, old: Path) -> Path:
    """``history/KEY.STAMP.yaml``: the old entry's date written, else its commit's first 12 characters."""
    try:
        data = yaml.safe_load(old.read_text()) or {}
    except yaml.YAMLError:
        data = {}
    data = data if isinstance(data, dict) else {}
    stamp = str(data.get("written") or str(data.get("commit") or "unknown")[:12])
    stamp = "".join(c if c.isalnum() or c in "-_" else "-" for c in stamp)
    folder = Path(registry) / task / algo / HISTORY
    kept, n = folder / f"{key}.{stamp}.yaml", 1
    while kept.exists():
        n += 1
        kept = folder / f"{key}.{stamp}.{n}.yaml"
    return kept


def _plain(v):
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def read_entry(path: Path) -> Entry:
    """An entry read as untrusted input: bounded YAML, the schema, every field of ``config`` (and of
    ``candidate``) against its algorithm's declaration; a ValueError of one line naming the file and
    what is wrong."""
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
        for part in ("config", "candidate"):
            for name, value in (getattr(entry, part) or {}).items():
                check_field(name, value, (entry.algo,), (part, name))
        if entry.schedule is not None:  # as a sweep file's group schedule is checked (changeable fields)
            from sweeps.sweep_file import Group, check_changeable

            try:
                steps = Group.model_validate({"schedule": list(entry.schedule)}).schedule
            except ValidationError as e:
                err = e.errors()[0]
                raise FieldError(err["loc"], err["msg"]) from None
            for i, step in enumerate(steps):
                for name, value in step.set.items():
                    check_field(name, value, (entry.algo,), ("schedule", i, "set", name))
                check_changeable(step.set, (entry.algo,), ("schedule", i, "set"))
    except FieldError as e:
        raise ValueError(f"{path}: {'.'.join(map(str, e.loc))}: {e.message}") from None
    return entry


def tuned_entry(registry: Path, task: str, algo: str, budget, limit: float | dict, environment: Callable[[dict], dict],
                trial: str = "", tuned_limit: float | None = None) -> tuple[Path, Entry]:
    """The entry ``preset: tuned`` starts a trial of ``algo`` on ``task`` from: tuned at ``budget``, at
    the trial's ``limit`` (or at ``tuned_limit``, where the sweep file names one), in the environment
    the trial has with the entry's fields applied (``environment``: those fields → the trial's
    fingerprint). Refused in one line where there is no entry, or none at that budget, that limit or
    in that environment (the first such entry's difference named)."""

    registry = Path(registry)
    paths = entry_paths(registry, task, algo)
    if not paths:
        have = sorted(str(p.relative_to(registry)) for p in _current(registry)) if registry.is_dir() else []
        raise ValueError(f"preset: tuned: the registry {registry} has no entry for {algo} on {task}; accepted: "
                         f"{', '.join(have) or 'none yet'} (a tuned comparison writes them: tune: in a sweep file)")
    found = []
    for p in paths:
        e = read_entry(p)
        if e.task != task or e.algo != algo:
            raise ValueError(f"{p}: an entry of {e.algo} on {e.task} filed as {algo} on {task}; refused")
        found.append((p, e))
    at_budget = [(p, e) for p, e in found if str(e.budget) == str(budget)]
    if not at_budget:
        p, e = found[0]
        budgets = ", ".join(dict.fromkeys(str(e.budget) for _, e in found))
        raise ValueError(f"preset: tuned: {p} was tuned at budget {e.budget}, this sweep's is {budget}; "
                         f"accepted: budget {budgets}, or tune at {budget}")
    if isinstance(limit, dict):  # a trial with a limit per constraint: an entry tuned at those limits
        want_limits = named_limits(limit)
        at_limits = [(p, e) for p, e in at_budget if named_limits(e.constraints) == want_limits]
        if not at_limits:
            p, e = at_budget[0]
            had = named_limits(e.constraints) or {"the summed cost": e.cost_limit}
            raise ValueError(f"preset: tuned: {p} was tuned at limits {_limits_text(had)}, trial {trial} runs at "
                             f"{_limits_text(want_limits)}; accepted: an entry tuned at those limits")
        return _in_environment(at_limits, environment, trial)
    want = float(limit if tuned_limit is None else tuned_limit)
    at_limit = [(p, e) for p, e in at_budget if math.isclose(e.cost_limit, want, rel_tol=1e-9, abs_tol=1e-12)
                and not named_limits(e.constraints)]
    if not at_limit and all(named_limits(e.constraints) for _, e in at_budget):
        p, e = at_budget[0]
        raise ValueError(f"preset: tuned: {p} was tuned with a limit per constraint "
                         f"({_limits_text(named_limits(e.constraints))}), trial {trial} runs one limit "
                         f"{_num(want)} on the summed cost; accepted: constraints: {{...}} at those limits in the "
                         "sweep file, or an entry tuned on the summed cost")
    if not at_limit:
        p, e = at_budget[0]
        limits = ", ".join(dict.fromkeys(_num(e.cost_limit) for _, e in at_budget))
        if tuned_limit is not None:
            raise ValueError(f"preset: tuned: tuned_limit {_num(want)}: the registry {registry} has no entry for "
                             f"{algo} on {task} at budget {budget} tuned at that limit; accepted: tuned_limit "
                             f"{limits}")
        raise ValueError(f"preset: tuned: {p} was tuned at limit {_num(e.cost_limit)}, trial {trial} runs at "
                         f"{_num(want)}; accepted: an entry tuned at {_num(want)}, or tuned_limit: "
                         f"{_num(e.cost_limit)} in the sweep file to start every trial from the limit-"
                         f"{_num(e.cost_limit)} entry")
    return _in_environment(at_limit, environment, trial)


def _limits_text(limits: dict) -> str:
    return ", ".join(f"{n} {_num(b)}" for n, b in sorted(limits.items()))


def _in_environment(found: list, environment: Callable[[dict], dict], trial: str) -> tuple[Path, Entry]:
    """The first of ``found`` (path, entry) tuned in the environment the trial has with its fields
    applied, or a one-line refusal naming the first one's difference."""
    from lac_rllib.tasks.fingerprint import differences, fingerprint_id

    first = None
    for p, e in found:
        now = environment(applied(e))
        if fingerprint_id(now) == e.fingerprint_id:  # read_entry checked the id is its fingerprint's
            return p, e
        first = first or (p, e, now)
    p, e, now = first
    raise ValueError(f"preset: tuned: {p} was tuned in another environment: {differences(e.fingerprint, now)} "
                     f"(trial {trial}); accepted: an entry tuned in the environment the trial has")


def _current(registry: Path) -> list[Path]:
    """Every entry in ``registry`` but those kept in ``history/``."""
    return [p for p in sorted(Path(registry).glob("**/*.yaml")) if HISTORY not in p.relative_to(registry).parts]


def _unknown(v) -> str:
    return "unknown" if v is None else str(v)


def listing(registry: Path) -> str:
    """``lac-sweep registry``: one line per entry (its replaced ones counted); what an entry written
    before a field existed lacks is listed as unknown."""
    registry = Path(registry)
    paths = _current(registry) if registry.is_dir() else []
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
        fields = ", ".join(f"{k}={v}" for k, v in e.config.items())
        later = ""
        if e.schedule and len(e.schedule) > 1:  # a PBT winner: its fields change during training
            ats = ", ".join(f"{int(step['at']):,}" for step in e.schedule[1:])
            later = f" at first, then its schedule's at {ats} env steps"
        if e.verdict == DEFAULT_STANDS:
            tried = ", ".join(f"{k}={v}" for k, v in (e.candidate or e.config).items())
            what = f"the default stands (tuned {tried or '?'}{later} was not shown better)"
        else:
            what = fields + later
        missing = [name for name, v in (("verdict", e.verdict), ("searcher", e.searcher), ("samples", e.num_samples),
                                        ("random start", e.random_start), ("search space", e.search_space),
                                        ("per-seed scores", e.by_seed), ("paired gap", e.gap),
                                        ("interval methods", e.intervals), ("the commit's source", e.commit_source))
                   if v is None]
        search = (f"; search {e.searcher} × {e.num_samples} samples ({_unknown(e.random_start)} from its random start)"
                  if e.searcher and e.num_samples and e.searcher != "pbt" else
                  f"; search pbt, a population of {e.num_samples}" if e.searcher == "pbt" else "")
        lines.append(f"  {e.task} {e.algo} @ {e.budget} (limit {e.cost_limit:g}): {what}; verdict "
                     f"{_unknown(e.verdict)}; fresh seeds {len(e.fresh_seeds)}: return {_g(f.return_mean)}, cost "
                     f"{_g(f.cost_mean)} (default {_g(e.default_fresh.return_mean)}, {_g(e.default_fresh.cost_mean)})"
                     + ("" if e.gap is None else f", paired gap {_gap_text(e.gap)}") + search
                     + f"; commit {e.commit[:12]}{_commit_from(e.commit_source)}; env {e.fingerprint_id}"
                     + ("" if e.search_feasible else "; its search had nothing feasible: the least costly")
                     + (f"; unknown (written before they were recorded): {', '.join(missing)}" if missing else ""))
    kept = [p for p in sorted(registry.glob(f"**/{HISTORY}/*.yaml"))]
    if kept:
        lines.append(f"  and {len(kept)} replaced entr{'y' if len(kept) == 1 else 'ies'} kept in {HISTORY}/ folders")
    return "\n".join(lines)


def _commit_from(source: str | None) -> str:
    if source is None:
        return ""
    return " (the search's)" if source == COMMIT_FROM_SEARCH else " (when written: the search's not found)"


def _g(x) -> str:
    return "unknown" if x is None else f"{x:.3g}"
