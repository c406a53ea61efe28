"""The resolved sweep: a sweep file (``--config``, or a built-in ``--space``) with the command
line's flags and the defaults applied, checked again as a whole: what every later step reads,
and what ``sweep.yaml`` records. Also what a resolved sweep says of its algorithms.

``args`` is the command line's flags as sweeps/run.py parses them (a flag left out is None: the
file, else its default, decides).
"""

from __future__ import annotations

import ast
import os
from pathlib import Path

from pydantic import ValidationError

from lac_rllib.algorithms.registry import ALGO_FIELD, check_algo, is_builtin, module_dir
from sweeps import spaces, sweep_file
from sweeps.sweep_file import SweepFile

#: The flag each resolved key of a sweep comes from when it is given (sweep_file.Origin).
FLAG_OF = {"task": "--task", "budget": "--budget", "num_samples": "--num-samples", "scheduler": "--scheduler",
           "max_concurrent": "--max-concurrent", "cpus_per_trial": "--cpus-per-trial",
           "experiment": "--experiment", "name": "--name", "cost_limits": "--cost-limits"}


def module_search_dirs(args) -> tuple[str, ...]:
    """Where a user's module (an env factory's, an algorithm's) is looked up after the Python path:
    beside the sweep file, then here."""
    return tuple(dict.fromkeys(((str(Path(args.config).resolve().parent),) if args.config else ())
                               + (os.getcwd(),)))


def resolve_sweep(args) -> tuple[SweepFile, str, sweep_file.Origin]:
    """The sweep file (``--config``, or the built-in ``--space``) with the flags and the defaults
    applied, checked again as a whole: the sweep every later step reads, and ``sweep.yaml``.
    Returns it, the sweep's kind (the built-in space or the file's stem) and where each key came from."""
    path = Path(args.config) if args.config else sweep_file.builtin_path(args.space)
    base, origin = sweep_file.load_with_origin(path)
    dirs = module_search_dirs(args)
    space = args.space or path.stem
    data = base.model_dump(exclude_none=True)
    if args.task:
        data["task"] = [args.task]
    if args.budget is not None:
        data["budget"] = args.budget
    if args.seeds is not None or args.seed_start is not None:
        old = base.seed_list()
        data["seeds"] = {"count": args.seeds or len(old),
                         "start": args.seed_start if args.seed_start is not None else old[0]}
    algo_pairs = [p for p in args.set if p.partition("=")[0].strip() == ALGO_FIELD]
    cli_sets = parse_set_pairs([p for p in args.set if p not in algo_pairs])
    if algo_pairs:
        try:
            algo = check_algo(algo_pairs[-1].partition("=")[2].strip(), dirs)
        except ValueError as e:
            raise ValueError(f"--set {ALGO_FIELD}: {e}") from None
        if sweeps_algo(base):
            raise ValueError(f"--set {algo_pairs[-1]}: {path.name} sweeps algo itself ({list(swept_algos(base))}); "
                             "accepted: --set of fields every algorithm it runs has")
        data["algo"] = [algo]
    # --set constraints.NAME=b: one limit of the file's constraints (or a new one), the rest kept.
    limits = {name.partition(".")[2]: cli_sets.pop(name) for name in list(cli_sets) if name.startswith("constraints.")}
    if isinstance(cli_sets.get("constraints"), dict):
        limits = {**cli_sets.pop("constraints"), **limits}
    if limits:
        data["constraints"] = {**(data.get("constraints") or {}), **limits}
    data["set"] = {**data.get("set", {}), **cli_sets}
    for key in ("num_samples", "scheduler", "max_concurrent", "cpus_per_trial", "experiment", "cost_limits"):
        if getattr(args, key) is not None:
            data[key] = getattr(args, key)
    tune_flags = {}
    if getattr(args, "tune", None) or getattr(args, "tune_seeds", None) or (data.get("tune") and args.confirm_seeds):
        tune = dict(data.get("tune") or {})
        for key, flag, value in (("num_samples", "--tune", args.tune), ("seeds", "--tune-seeds", args.tune_seeds),
                                 ("confirm_seeds", "--confirm-seeds", args.confirm_seeds)):
            if value is not None:
                tune[key] = {"count": value} if key == "seeds" else value
                tune_flags[("tune", key)] = flag
        data["tune"] = tune
    flags = {(k,): f for k, f in FLAG_OF.items() if getattr(args, k) is not None} | tune_flags
    flags |= {("set", k): f"--set {k}" for k in cli_sets}
    if limits:
        flags[("constraints",)] = "--set constraints"
    if algo_pairs:
        flags[("algo",)] = f"--set {ALGO_FIELD}"
    if args.seeds is not None:
        flags[("seeds", "count")] = "--seeds"
    if args.seed_start is not None:
        flags[("seeds", "start")] = "--seed-start"
    origin = origin.with_flags(flags)
    data.setdefault("task", [spaces.DEFAULT_TASK])
    data.setdefault("budget", "quick")
    data.setdefault("seeds", {"count": 3, "start": 0})
    data.setdefault("searcher", "tpe" if base.is_search else "grid")
    data.setdefault("scheduler", "none")
    data.setdefault("score", "train" if data.get("eval_episodes") == 0 else "eval")
    data.setdefault("cpus_per_trial", 1)
    data.setdefault("experiment", "lac-sweeps")
    if base.searcher == "pbt":  # a member per seed: the population's seeds from the sweep's first on
        members = (base.pbt or sweep_file.PBTSpec()).members
        seeds = sweep_file.Seeds.model_validate(data["seeds"]).values()
        if (base.seeds is not None or args.seeds is not None) and len(seeds) != members:
            raise ValueError(f"{origin(('seeds',))}: {len(seeds)} seeds with pbt.members {members}: each member is "
                             f"one seed; accepted: {members} seeds (seeds: {{count: {members}, start: {seeds[0]}}}), "
                             f"or no seeds (0..{members - 1}; --seed-start S moves them)")
        if len(seeds) != members:  # the default 3 seeds: the population's from the first
            data["seeds"] = {"count": members, "start": seeds[0]}
        data.setdefault("pbt", {})
    if base.is_search:
        if base.searcher != "pbt":
            data.setdefault("num_samples", 20)
        if data["search"] == "default" or "default" in data["search"].values():
            data["search"] = _declared_search(data, origin)
        if base.searcher == "pbt":
            _changeable_only(data, origin)
    elif "groups" not in data:  # the file's one group (or one configuration), named after the file
        group = sweep_file.safe_name(space)
        data["groups"] = {group: {"grid": data.pop("grid", {})}} if data.get("grid") else {group: {}}
    try:
        sweep = SweepFile.model_validate(data, context={"search_dirs": dirs})
        sweep_file.check_fields(sweep, dirs)
    except sweep_file.FieldError as e:
        raise ValueError(f"{origin(e.loc)}: {e.message}") from None
    except ValidationError as e:  # a flag's value the file's schema refuses
        raise ValueError(sweep_file.first_error(e, origin)) from None
    if args.name or not sweep.name:
        tasks = sweep.task
        what = ((tasks[0] if isinstance(tasks[0], str) else tasks[0].task_id()).split("/")[-1]
                if len(tasks) == 1 else f"{len(tasks)}-tasks")
        # Derived from the file's stem and the task: made safe rather than refused (it becomes a path).
        sweep = sweep.model_copy(update={"name": args.name or sweep_file.safe_name(f"{space}-{what}-{sweep.budget}")})
    return sweep, space, origin


def _declared_search(data: dict, origin) -> dict:
    """The file's ``search: default`` (or a field's ``default``) as the algorithm's declared ranges
    on the sweep's task and budget (spaces.declared_search)."""
    from lac_rllib.tasks import get_task

    search = data["search"]
    if isinstance(search, dict) and ALGO_FIELD in search:
        raise ValueError(f"{origin(('search', ALGO_FIELD))}: a search over algo with default ranges: each "
                         "algorithm has its own space; accepted: one algorithm per search (or tune: for several)")
    task = data["task"][0]
    task = task if isinstance(task, str) else sweep_file.UserEnv.model_validate(task).task_id()
    try:
        get_task(task)  # a user's env is registered when the plan builds it: its ranges need its defaults
    except ValueError:
        raise ValueError(f"{origin(('search',))}: default ranges on a user's env: give each field's distribution "
                         "(its defaults are known once the env is built)") from None
    try:
        return spaces.declared_search(data["algo"][0], task, data["budget"], data.get("set", {}), search,
                                      changeable=data.get("searcher") == "pbt")
    except ValueError as e:
        raise ValueError(f"{origin(('search',))}: {e}") from None


def _changeable_only(data: dict, origin) -> None:
    """PBT changes its searched fields mid-run: each must be one its algorithm declares changeable."""
    from lac_rllib.algorithms.registry import algo_config

    algo = data["algo"][0]
    changeable = algo_config(algo).changeable_fields()
    for name in data["search"]:
        if name not in changeable:
            raise ValueError(f"{origin(('search', name))}: {name} is not a field {algo} can change mid-run; accepted "
                             f"with searcher pbt: {', '.join(changeable) or 'none'}")


def parse_set_pairs(pairs: list[str]) -> dict:
    """``--set FIELD=VALUE`` pairs as values (Python literals, else the text); their names and
    values are checked with the sweep's fields (``sweep_file.check_fields``)."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--set {pair!r}: expected FIELD=VALUE")
        try:
            out[name.strip()] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[name.strip()] = raw  # plain strings such as informative / next
    return out


def swept_algos(sweep: SweepFile) -> tuple:
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    found = [v for g in groups for v in g.grid.get(ALGO_FIELD, ())]
    if sweep.search and ALGO_FIELD in sweep.search:
        found += list(sweep.search[ALGO_FIELD].values_to_check())
    if sweep.grid and ALGO_FIELD in sweep.grid:
        found += list(sweep.grid[ALGO_FIELD])
    return tuple(dict.fromkeys(found))


def user_algos(sweep: SweepFile) -> dict[str, str]:
    """Each user's algorithm the sweep names (checked when the file was read) → the folder its
    trials import it from (Ray's workers do not share this process's path)."""
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    named = [*sweep.algo, *swept_algos(sweep), *(s[ALGO_FIELD] for s in (sweep.set, *(g.set for g in groups))
                                                 if ALGO_FIELD in s)]
    return {a: module_dir(a) for a in dict.fromkeys(named) if not is_builtin(a)}


def sweeps_algo(sweep: SweepFile) -> bool:
    return bool(swept_algos(sweep)) or len(sweep.algo) > 1

