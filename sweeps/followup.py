"""What follows a finished sweep: its trials read back from MLflow, its winners handed on, and the
confirmation that reruns them on fresh seeds as a sweep of its own, ``NAME-confirm``.

Two flows confirm: ``--confirm-top K`` (a sweep's K best feasible configurations beside its default
and baselines: :func:`confirm_top`, judged by sweeps/reports/confirm.py) and a tuned comparison
(every algorithm's winners beside its default: sweeps/tuned.py). Both read a sweep back with
:func:`read_back`, take its winners from sweeps/reports/verdicts.py ``choose_winners`` and build the
confirmation with :func:`build_confirmation`. Nothing here plans or runs a sweep (sweeps/plan.py and
sweeps/tuned.py plan what this module builds), so the planning modules may import it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pandas as pd

from sweeps.record import SWEEP_FILE
from sweeps.sweep_file import SweepFile

#: A confirmation is the sweep ``NAME-confirm`` (its space in the plan: ``confirm``).
CONFIRM = "confirm"
#: What a confirmation does not take from the sweep it confirms: how that sweep chose its
#: configurations (the groups replace it) and its name, seeds, budget and description.
NOT_CONFIRMED = ("search", "grid", "groups", "groups_at", "searcher", "num_samples", "env_steps_budget", "tune", "pbt",
                 "name", "seeds", "budget", "description")


def confirmation_name(name: str) -> str:
    """The name of the confirmation of the sweep ``name``."""
    return f"{name}-{CONFIRM}"


def read_back(plan, fields=()) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A finished sweep's trials (each with its values of ``fields``) and their summary (empty
    without a trial), read back from MLflow under the parent run its directory records."""
    from sweeps.record import parent_run_id
    from sweeps.reports.report import summarize
    from sweeps.reports.results import sweep_results
    from sweeps.tracking import SweepTracker

    tracker = SweepTracker(plan.tracking_uri, plan.experiment)
    trials, _ = sweep_results(tracker, parent_run_id(Path(plan.storage) / plan.name), tuple(fields))
    return trials, summarize(trials) if len(trials) else pd.DataFrame()


def fields_of(trials: pd.DataFrame, fields) -> dict[str, dict]:
    """Each configuration's ``config`` label → its values of ``fields`` (a value it lacks left out)."""
    return {r["config"]: {f: r[f] for f in fields if f in r and not _missing(r[f])} for r in trials.to_dict("records")}


def build_confirmation(sweep: SweepFile, groups: dict, search_seeds, count: int, budget, name: str, description: str,
                 drop: tuple[str, ...] = (), task: str | None = None) -> SweepFile:
    """The confirmation sweep: ``sweep`` with ``groups`` (name → {"set": fields}) in place of how it
    chose its configurations, a grid on ``count`` fresh seeds (none of whose streams ``search_seeds``
    drew from: sweeps/seeds.py) at ``budget``. ``drop``: the sweep's keys its groups set instead (its
    ``algo`` where each group names its own, its ``set`` where each group carries it); ``task``: the
    one task it reruns."""
    from sweeps.seeds import fresh_seeds

    data = sweep.model_dump(exclude_none=True, exclude={*NOT_CONFIRMED, *drop})
    return SweepFile.model_validate({**data, **({"task": [task]} if task else {}), "groups": groups,
                                     "budget": budget, "name": name, "searcher": "grid",
                                     "seeds": {"list": fresh_seeds(search_seeds, count)}, "description": description})


def confirmation_file(sweep: SweepFile, top: list[dict], seeds: int, budget, name: str,
                      baselines: tuple[str, ...] = ()) -> SweepFile:
    """``--confirm-top``'s confirmation: one group per winner (its fields as the group's ``set``), the
    default and the ``baselines`` the sweep ran (each algorithm's own defaults, group
    ``baseline-ALGO``), on ``seeds`` fresh seeds, at ``budget``."""
    from sweeps.reports.confirm import BASELINE, DEFAULT_GROUP

    # A sweep of several algorithms (``algo: [...]``): each winner names its own, and there is no one default.
    several = len(sweep.algo) > 1
    groups = {w["group"]: {"set": w["fields"], **({"schedule": w["schedule"]} if w.get("schedule") else {})}
              for w in top} | ({} if several else {DEFAULT_GROUP: {}})
    groups |= {f"{BASELINE}{algo}": {"set": {"algo": algo}} for algo in baselines}
    return build_confirmation(sweep, groups, sweep.seed_list(), seeds, budget, name, f"confirmation of {sweep.name}",
                        drop=("algo",) if several else ())


def confirm_top(plan) -> tuple[SweepFile, list[dict]] | None:
    """``--confirm-top``'s hand-off from the finished sweep ``plan``: its winners (by the lower end of
    their return interval, or by their worst or mean regret over a ladder) and the confirmation that
    reruns them beside the default and the baselines the sweep ran. None: no winner."""
    from lac_rllib.algorithms.registry import DEFAULT_ALGO
    from sweeps.reports import confirm

    k, seeds, budget, by = (*plan.confirm, confirm.BY_RETURN)[:4]
    # Over several algorithms (``algo: [...]``) a configuration is also its algorithm.
    fields = [*confirm.varied_fields(plan.sweep), *(["algo"] if len(plan.sweep.algo) > 1 else [])]
    trials, summary = read_back(plan, fields)
    values = fields_of(trials, fields)
    if not len(trials):
        top = []
    elif plan.sweep.searcher == "pbt":  # a member's schedule, not a point (sweeps/pbt.py)
        from sweeps.pbt import winners, with_schedules
        from sweeps.record import parent_run_id
        from sweeps.tracking import SweepTracker

        client = SweepTracker(plan.tracking_uri, plan.experiment).client
        top = winners(with_schedules(trials, client, parent_run_id(Path(plan.storage) / plan.name)), k)
    elif by == confirm.BY_RETURN:
        top = confirm.with_limits(confirm.winners(summary, values, k), trials)
    else:
        top = confirm.regret_winners(trials, values, k, by)
    if not top:
        return None
    # The baselines the sweep ran (besides its own algorithm) rerun at their defaults beside the winners.
    baselines = tuple(a for a in dict.fromkeys(trials["algo"]) if a not in plan.sweep.algo and a != DEFAULT_ALGO)
    return confirmation_file(plan.sweep, top, seeds, budget, confirmation_name(plan.name), baselines), top


def confirmation_infra(infra, storage: str, name: str):
    """The confirmation ``name``'s infra: resumed where its directory records it (stopped after it
    started), else a new sweep."""
    return dataclasses.replace(infra, resume=(Path(storage) / name / SWEEP_FILE).exists())


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and v != v)
