"""A tuned comparison (a sweep file's ``tune:``): every algorithm tuned as LAC is, at equal budgets.

Comparing one tuned algorithm with untuned ones is the unfairness the literature names (Eimer,
Lindauer & Raileanu, ICML 2023; Hamilton et al. 2022). Here each algorithm the sweep runs
(``algo: [...]`` or a grid over ``algo``) gets the same search: its own declared search space
(lac_rllib/constrained/search_space.py), ``tune.num_samples`` configurations × ``tune.seeds`` seeds
× the budget's env steps under the same searcher, one sweep ``NAME-tune-ALGO`` each (refused before
Ray starts unless the budgets are equal: :func:`check_equal_budgets`). Then one confirmation
``NAME-confirm`` reruns every algorithm's best configuration (``ALGO-tuned1``…) beside its default
(``ALGO-default``) on ``tune.confirm_seeds`` fresh seeds, and the report (sweeps/reports/tuned.py)
says per algorithm what tuning changed; each verdict goes to the registry (sweeps/tuned_registry.py):
the tuned configuration where the paired test on the fresh seeds showed it better, else that the
default stands.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pandas as pd

from sweeps import followup, spaces
from sweeps.plan import Plan, plan_sweep
from sweeps.record import SWEEP_FILE
from sweeps.reports.tuned import DEFAULT, TUNED
from sweeps.seeds import fresh_seeds, seeds_text
from sweeps.sweep_file import SweepFile, check_fields

TUNE = "tune"
#: The data a tuned comparison's report is rendered from (sweeps/reports/rendered.py renders it again):
#: the resolved sweep file, each search's trials, the confirmation's trials.
SWEEP, SEARCH, CONFIRMATION = "sweep.yaml", "search-{algo}.csv", "confirmation.csv"


@dataclasses.dataclass(frozen=True)
class TunedPlan:
    """The plans of a tuned comparison: one search per algorithm, then the joint confirmation."""

    sweep: SweepFile  #: the resolved sweep file with its ``tune:``
    searches: dict  #: algo → its search's Plan
    registry: Path  #: where the verdicts are written (tuned/<task>/<algo>/<key>.yaml, sweeps/tuned_registry.py)
    #: Whether ``--registry`` named it: a smoke comparison writes into a registry only then.
    registry_asked: bool = False

    @property
    def name(self) -> str:
        return self.sweep.name

    @property
    def task(self) -> str:
        return next(iter(self.searches.values())).tasks[0]

    def check(self) -> None:
        """Before Ray starts: each search's directory, except a search's that finished earlier (read
        back, not run again: :func:`run_tuned`)."""
        from sweeps.record import checked_sweep_dir

        for plan in self.searches.values():
            if plan.infra.resume or not (Path(plan.storage) / plan.name).exists():
                checked_sweep_dir(plan)

    def run(self, run_plan) -> int:
        """The comparison (:func:`run_tuned`), each sweep run by ``run_plan``: its exit code."""
        return run_tuned(self, run_plan)


def _group_algos(sweep: SweepFile, group) -> tuple[str, ...]:
    """The algorithms a group runs: its grid's over ``algo``, else its set's, else the sweep's."""
    return tuple(group.grid.get("algo") or ((group.set["algo"],) if "algo" in group.set else sweep.algo))


def tuned_algos(sweep: SweepFile) -> tuple[str, ...]:
    """The algorithms a tuned comparison tunes: those its groups run (a grid over ``algo``, or one
    group per algorithm as the paper's tables have), else the sweep's ``algo``."""
    groups = (sweep.groups or {}).values()
    return tuple(dict.fromkeys(a for g in groups for a in _group_algos(sweep, g))) or tuple(sweep.algo)


def search_sweep(sweep: SweepFile, algo: str, task: str) -> SweepFile:
    """``algo``'s search: its declared space on ``task`` at the sweep's budget, with the tune's searcher,
    samples and seeds, the sweep's ``set`` and the fields its groups set beside ``algo`` (a table's
    per-algorithm preset)."""
    groups = [g for g in (sweep.groups or {}).values() if algo in _group_algos(sweep, g)]
    sets = {**sweep.set, **{k: v for g in groups for k, v in g.set.items() if k != "algo"}}
    data = sweep.model_dump(exclude_none=True, exclude={"tune", "groups", "grid", "groups_at", "algo", "name", "seeds",
                                                         "searcher", "num_samples", "description", "set"})
    t = sweep.tune
    pbt = t.searcher == "pbt"  # a population over the changeable fields, a member per seed
    search = spaces.declared_search(algo, task, sweep.budget, sets, "default", changeable=pbt)
    how = ({"pbt": t.pbt.model_dump(exclude_none=True), "seeds": {"count": t.pbt.members, "start": 0}} if pbt else
           {"num_samples": t.num_samples, "seeds": t.seeds.model_dump(exclude_none=True)})
    out = SweepFile.model_validate({**data, "algo": [algo], "set": sets, "search": search, "searcher": t.searcher,
                                    **how, "task": [task], "name": f"{sweep.name}-{TUNE}-{algo}",
                                    "description": f"{sweep.name}: {algo} over its search space"})
    check_fields(out)
    return out


def budget_of(plan: Plan) -> tuple[int, int, int]:
    """A search's budget: (configurations, seeds each, env steps per trial); a population's: (members, 1, env steps)."""
    if plan.pbt is not None:
        return plan.sweep.pbt.members, 1, plan.timesteps
    return plan.sweep.num_samples, len(plan.seeds), plan.timesteps


def check_equal_budgets(budgets: dict) -> None:
    """Every algorithm's search at the same configurations × seeds × env steps, else a ValueError
    naming the first that differs from the first algorithm's."""
    items = list(budgets.items())
    first_algo, first = items[0]
    for algo, b in items[1:]:
        if tuple(b) != tuple(first):
            raise ValueError(f"tune: unequal budgets: {algo} gets {_budget_text(b)}, {first_algo} "
                             f"{_budget_text(first)}; accepted: the same samples × seeds × env steps for all")


def _budget_text(b) -> str:
    return f"{b[0]} samples × {b[1]} seeds × {b[2]:,} env steps"


def make_tuned_plans(sweep: SweepFile, space: str, infra, search_dirs=(), origin=None, max_trials: int = 5_000,
                     registry: Path | None = None) -> list[TunedPlan]:
    """One tuned comparison per task of the sweep (a table's tasks are tuned one by one: tuned
    configurations are per task), each named ``NAME`` (one task) or ``NAME-TASK``."""
    from sweeps.plan import resolve_tasks
    from sweeps.sweep_file import safe_name

    tasks, _ = resolve_tasks(sweep, search_dirs, origin)
    if len(tasks) == 1:
        return [make_tuned_plan(sweep, space, infra, search_dirs, origin, max_trials, registry)]
    return [make_tuned_plan(sweep.model_copy(update={"task": (t,), "name": safe_name(f"{sweep.name}-{t.split('/')[-1]}")
                                                      }), space, infra, search_dirs, origin, max_trials, registry)
            for t in tasks]


def make_tuned_plan(sweep: SweepFile, space: str, infra, search_dirs=(), origin=None, max_trials: int = 5_000,
                    registry: Path | None = None) -> TunedPlan:
    """Every algorithm's search on the sweep's task planned (a user's env built once), their budgets
    checked equal."""
    from sweeps.plan import resolve_tasks
    from sweeps.tuned_registry import DEFAULT_REGISTRY

    tasks, _ = resolve_tasks(sweep, search_dirs, origin)
    searches = {}
    for algo in tuned_algos(sweep):
        sub = search_sweep(sweep, algo, tasks[0])
        own = dataclasses.replace(infra, resume=infra.resume and (Path(infra.storage) / sub.name / SWEEP_FILE).exists())
        searches[algo] = plan_sweep(sub, TUNE, own, search_dirs, origin, max_trials=max_trials)
    check_equal_budgets({a: budget_of(p) for a, p in searches.items()})
    return TunedPlan(sweep=sweep, searches=searches, registry=Path(registry or DEFAULT_REGISTRY),
                     registry_asked=registry is not None)


def print_tuned_plan(tp: TunedPlan) -> None:
    """The comparison's budgets before anything runs: equal by construction, said per algorithm."""
    from sweeps.search import configurations_at_once, search_text

    t = tp.sweep.tune
    how = {"tpe": "TPE with the feasibility constraint", "random": "random search",
           "pbt": "population-based training ranked by the one feasibility rule"}[t.searcher]
    print(f"tuned comparison '{tp.name}': {', '.join(tp.searches)} on {tp.task}, budget {tp.sweep.budget}, {how}")
    first = next(iter(tp.searches.values()))
    if first.pbt is None:
        at_once = configurations_at_once(first.concurrency, len(first.seeds))
        print(f"  each search: {search_text(t.searcher, t.num_samples, at_once)}")
    else:
        print(f"  each search: {t.pbt.members} members exploiting every {' / '.join(f'{i:,}' for i in first.pbt)} "
              "env steps; its best member's schedule is what is confirmed")
    for algo, p in tp.searches.items():
        n, seeds, steps = budget_of(p)
        print(f"  {algo:>10}: {_budget_text((n, seeds, steps))} = {n * seeds * steps:,} env steps, "
              f"~{p.estimated_cpu_h:.2f} CPU-hours (its speed), search over {', '.join(p.sweep.search)}")
    print(f"  then: each algorithm's best {t.top} beside its default on {t.confirm_seeds} fresh seeds "
          f"({seeds_text(fresh_of(tp))}: sweeps/seeds.py), all in one confirmation "
          f"'{followup.confirmation_name(tp.name)}'")
    from sweeps.tuned_registry import destination

    where, why = destination(tp)
    print(f"  registry: {where}" + (f" ({why})" if why else "") + ": each algorithm's tuned configuration where the "
          "paired test on the fresh seeds shows it better than its default, else that the default stands",
          flush=True)


def fresh_of(tp: TunedPlan) -> tuple[int, ...]:
    """The confirmation's fresh seeds: none of their random streams any search's seeds drew from
    (sweeps/seeds.py)."""
    return fresh_seeds(_search_seeds(tp), tp.sweep.tune.confirm_seeds)


def _search_seeds(tp: TunedPlan) -> set[int]:
    return {s for p in tp.searches.values() for s in p.seeds}


def confirmation_sweep(tp: TunedPlan, winners: dict) -> SweepFile:
    """One sweep of every algorithm's winners (``ALGO-tunedK``) and default (``ALGO-default``) on the
    fresh seeds (:func:`fresh_of`), at the same budget (sweeps/followup.py ``build_confirmation``)."""
    groups = {}
    for algo, tops in winners.items():
        own = dict(tp.searches[algo].sweep.set)  # the sweep's set and its groups' (a table's preset)
        for k, w in enumerate(tops, 1):  # a PBT winner: its schedule replayed (sweeps/pbt.py)
            groups[f"{algo}-{TUNED}{k}"] = {"set": {**own, "algo": algo, **w["fields"]},
                                             **({"schedule": w["schedule"]} if w.get("schedule") else {})}
        groups[f"{algo}-{DEFAULT}"] = {"set": {**own, "algo": algo}}
    return followup.build_confirmation(
        tp.sweep, groups, _search_seeds(tp), tp.sweep.tune.confirm_seeds, tp.sweep.budget,
        followup.confirmation_name(tp.name), f"confirmation of {tp.name}: each algorithm tuned and default",
        drop=("algo", "set"), task=tp.task)


def pick_winners(summary, fields_of: dict, k: int) -> list[dict]:
    """A search's ``k`` best configurations (sweeps/reports/verdicts.py ``choose_winners``): the
    feasible ones by the lower end of their return interval, a sample that is the default among
    them, else, where none is feasible, the least costly, ``feasible`` False: every algorithm has a
    tuned configuration to confirm (it may fail to hold up)."""
    from sweeps.reports.verdicts import choose_winners

    rows = choose_winners(summary, k, fields_of, least_costly_fallback=True, default_competes=True)
    return [{"config": r["config"], "fields": fields_of.get(r["config"], {}), "feasible": bool(r["feasible"]),
             "search": {c: _plain(r.get(c)) for c in ("return_mean", "return_mean_ci_low", "return_mean_ci_high",
                                                      "cost_mean", "feasible_fraction", "n_seeds")}}
            for r in rows.to_dict("records")]


def search_winners(tp: TunedPlan, algo: str, trials, summary=None) -> list[dict]:
    """``algo``'s winners (:func:`pick_winners`) from its search's ``trials`` (each with the values of
    the fields it searched) and their ``summary`` (summarized here where not given)."""
    from sweeps.reports.report import summarize

    if not len(trials):
        return []
    if tp.sweep.tune.searcher == "pbt":  # members' schedules (read back with them: run_tuned)
        from sweeps.pbt import winners

        return winners(trials, tp.sweep.tune.top, least_costly_fallback=True)
    fields = tp.searches[algo].sweep.search or ()
    summary = summarize(trials) if summary is None else summary
    return pick_winners(summary, followup.fields_of(trials, fields), tp.sweep.tune.top)


def tuned_report(tp: TunedPlan, searched: dict, confirmation) -> tuple[dict, dict, str]:
    """(winners, comparison, Markdown) of a tuned comparison from its data alone: ``searched``, algo →
    its search's trials; ``confirmation``, the confirmation's trials. The run writes its report with
    this, and sweeps/reports/rendered.py renders a committed folder with it again."""
    from sweeps.reports import tuned as report
    from sweeps.reports.report import summarize

    summaries = {algo: summarize(trials) if len(trials) else pd.DataFrame() for algo, trials in searched.items()}
    winners = {algo: search_winners(tp, algo, trials, summaries[algo]) for algo, trials in searched.items()}
    runs = {algo: (trials, summaries[algo], tp.searches[algo].timesteps) for algo, trials in searched.items()}
    comparison = report.comparison(runs, winners, confirmation)
    return winners, comparison, report.markdown(tp, comparison)


def _plain(v):
    return v.item() if hasattr(v, "item") else v


def run_tuned(tp: TunedPlan, run_plan) -> int:
    """Each algorithm's search, then the joint confirmation, then the report and the registry
    (``run_plan``: sweeps/run.py's, running one plan into its directory under its lock). A search
    already finished (``--resume`` after a stop) is read back, not run again."""
    from sweeps.record import checked_sweep_dir
    from sweeps.tracking import SweepTracker

    print_tuned_plan(tp)
    winners, searched = {}, {}
    for algo, plan in tp.searches.items():
        sweep_dir = Path(plan.storage) / plan.name
        if _finished(plan, sweep_dir):
            print(f"tune: {plan.name} finished earlier: its results are read back", flush=True)
        else:
            rc = run_plan(plan, checked_sweep_dir(plan))
            if rc != 0:
                return rc
        searched[algo], summary = followup.read_back(plan, plan.sweep.search or ())
        if plan.pbt is not None:  # each member's schedule beside its row: what its winner replays
            from sweeps.pbt import with_schedules
            from sweeps.record import parent_run_id

            searched[algo] = with_schedules(searched[algo], SweepTracker(plan.tracking_uri, plan.experiment).client,
                                            parent_run_id(sweep_dir))
        winners[algo] = search_winners(tp, algo, searched[algo], summary)
        if not winners[algo]:
            print(f"tune: {algo}'s search finished no configuration; nothing to confirm", flush=True)
            return 1
    cfile = confirmation_sweep(tp, winners)
    first = next(iter(tp.searches.values()))
    infra = followup.confirmation_infra(first.infra, first.storage, cfile.name)
    confirmation = plan_sweep(cfile, followup.CONFIRM, infra)
    if not _finished(confirmation, Path(confirmation.storage) / confirmation.name):
        rc = run_plan(confirmation, checked_sweep_dir(confirmation))
        if rc != 0:
            return rc
    from sweeps.record import parent_run_id
    from sweeps.tuned_registry import write_entries

    trials, _ = followup.read_back(confirmation)
    winners, comparison, text = tuned_report(tp, searched, trials)
    tracker = SweepTracker(confirmation.tracking_uri, confirmation.experiment)
    parent = parent_run_id(Path(confirmation.storage) / confirmation.name)
    tracker.client.log_text(parent, text, "tuned/report.md")
    here = Path(confirmation.storage) / confirmation.name
    (here / "tuned.md").write_text(text)
    # The data the report is rendered from, beside it (python -m sweeps.reports.rendered renders it again).
    write_tuned_data(here / "tuned-data", tp.sweep, searched, trials)
    written = write_entries(tp, comparison, winners, parent, {a: p for a, p in tp.searches.items()}, trials)
    print(text)
    print("registry: " + ", ".join(str(p) for p in written), flush=True)
    return 0


def write_tuned_data(folder: Path, sweep: SweepFile, searched: dict, confirmation: pd.DataFrame) -> None:
    """A tuned comparison's data into ``folder``: ``sweep`` (the resolved SweepFile), ``searched``
    (algo → its search's trials) and the ``confirmation``'s trials."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / SWEEP).write_text(sweep.dump())
    for algo, trials in searched.items():
        trials.to_csv(folder / SEARCH.format(algo=algo), index=False)
    confirmation.to_csv(folder / CONFIRMATION, index=False)


def _finished(plan: Plan, sweep_dir: Path) -> bool:
    """Whether the sweep in ``sweep_dir`` ran to its end (its parent run FINISHED in MLflow)."""
    if not (sweep_dir / SWEEP_FILE).exists():
        return False
    from sweeps.record import parent_run_id
    from sweeps.tracking import SweepTracker

    run = SweepTracker(plan.tracking_uri, plan.experiment).client.get_run(parent_run_id(sweep_dir))
    return run.info.status == "FINISHED"
