"""A sweep's results read back from MLflow (the record of every trial, resumed ones included), and
its close: the report on the parent run (summary, frontier, importances, safety, chain health,
a multi-objective search's Pareto set, a confirmation's verdict) and the note that leads it.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

import pandas as pd

from lac_rllib.algorithms.registry import DEFAULT_ALGO
from lac_rllib.constrained.metrics import (
    ACTOR_STD_MEAN,
    COST_LIMIT,
    COST_RATE,
    EPISODE_COST,
    EPISODE_RETURN,
    FEASIBLE,
    LANGEVIN_AT_BOUND,
    LANGEVIN_CLIP_FRACTION,
    per_constraint,
)
from sweeps.objective import OBJECTIVE, WALL_TIME_S, feasible, objective
from sweeps.reports.ladder import FRONTIER_GROUP
from sweeps.score import (
    EVAL,
    EVAL_COST,
    EVAL_RETURN,
    LAST_COST,
    LAST_RETURN,
    SCORE_TAG,
    TRAIN,
    TRAIN_COST,
    TRAIN_RETURN,
    constraint_limits,
    constraint_scores,
    declared,
    eval_score,
    joint_cost,
    joint_curve,
    joint_score,
    train_score,
)
from sweeps.tracking import (
    CONFIG_ID_TAG,
    CONFIG_TAG,
    DEFAULT_TAG,
    ENV_FINGERPRINT_JSON_TAG,
    ENV_FINGERPRINT_TAG,
    LADDER_CONSTRAINT_TAG,
    P_ALGO,
    P_GROUP,
    P_SEED,
    P_SWEPT_PARAM,
    P_SWEPT_VALUE,
    P_TASK,
    STATUS_TAG,
    STOPPED_TAG,
    SweepTracker,
    learning_curve,
    param_value,
)

#: Where Optuna 5's ``trial.set_constraint`` keeps the constraint the sweep hands it (sweeps/sweep.py).
OPTUNA_CONSTRAINT_KEY = "constraints:episode_cost_minus_limit"
#: The seconds a trial's evaluation blocks took, all together (sweeps/trainable.py).
EVAL_TIME_S = "eval_time_s"
#: The final-iteration metrics the chain-health flags read (sweeps/reports/chain_health.py).
CHAIN_FINAL = (LANGEVIN_AT_BOUND, LANGEVIN_CLIP_FRACTION, ACTOR_STD_MEAN)


def sweep_results(tracker: SweepTracker, parent: str, fields: tuple[str, ...] = ()) -> tuple[pd.DataFrame, dict]:
    """(trials, curves): one row per child run (its configuration, seed, status, final metrics and
    the values of ``fields``), and each trial's learning curve by trial id."""
    rows, curves = [], {}
    for run in tracker.children(parent):
        p, m, tid = run.data.params, run.data.metrics, run.data.tags.get("lac.trial_id", run.info.run_id)
        rows.append({"trial_id": tid, "group": p.get(P_GROUP, ""), "param": p.get(P_SWEPT_PARAM, ""),
                     "value": param_value(p.get(P_SWEPT_VALUE, "null")), "task": p.get(P_TASK),
                     "seed": int(p.get(P_SEED, 0)), "algo": p.get(P_ALGO, DEFAULT_ALGO),
                     "config": run.data.tags.get(CONFIG_TAG, ""), "config_id": run.data.tags.get(CONFIG_ID_TAG, ""),
                     "default": run.data.tags.get(DEFAULT_TAG) == "1",
                     ENV_COLUMN: run.data.tags.get(ENV_FINGERPRINT_TAG, ""),
                     ENV_JSON_COLUMN: run.data.tags.get(ENV_FINGERPRINT_JSON_TAG, ""),
                     "status": ("STOPPED" if run.data.tags.get(STOPPED_TAG) else "TERMINATED")
                     if run.info.status == "FINISHED" else "ERROR",
                     **{k: m.get(k, float("nan")) for k in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT, FEASIBLE,
                                                            OBJECTIVE, COST_RATE, *CHAIN_FINAL, EVAL_TIME_S,
                                                            WALL_TIME_S)},
                     **{k: param_value(p[k]) for k in ("langevin_steps", "langevin_step_size", "temperature", "beta",
                                                       *fields) if k in p}})
        limits = constraint_limits(m)
        rows[-1]["ladder_constraint"] = run.data.tags.get(LADDER_CONSTRAINT_TAG, "")
        curves[tid] = learning_curve(tracker.client, run.info.run_id, m.get(COST_LIMIT, float("nan")),
                                     tuple(limits))
        # The score the trial was ranked on when it ended (its tag); a run from before the tag: train.
        rows[-1] = scored(rows[-1], curves[tid], m, run.data.tags.get(SCORE_TAG, TRAIN))
        # Several constraints: the curve judged on the joint rule, as the trial is (sweeps/score.py).
        curves[tid] = joint_curve(curves[tid], limits, along=rows[-1].get("ladder_constraint") or None)
    # By trial id, not in the order MLflow lists the runs (the order they ran): a report is a function
    # of what was recorded, the same for any finish order.
    rows.sort(key=lambda r: str(r["trial_id"]))
    return split_environments(pd.DataFrame(rows)), curves


#: A trial's env fingerprint id and the whole (lac_rllib/tasks/fingerprint.py; its tags).
ENV_COLUMN, ENV_JSON_COLUMN = "env_fingerprint", "env_fingerprint_json"
#: How a task's runs in another environment are labelled: the task, then the fingerprint's id.
ENV_LABEL = " @env:"
#: Per trial split apart, the fingerprint (or its shared part) its ``TASK @env:ID`` label stands for.
ENV_SPLIT_COLUMN = "env_split"


def split_environments(trials: pd.DataFrame) -> pd.DataFrame:
    """Runs of one task in different environments (env fingerprints) are never ranked together: where
    a task's trials carry more than one, each is its own task, ``TASK @env:ID``, in every report
    (summary, frontier, ladder, table, confirmation, the tuned comparison). Two levels: what every
    algorithm on the task shares (the simulator, the task's settings, the cost) splits any runs; what
    an algorithm's own configuration decides (its observation filter, envs, kernels:
    lac_rllib/tasks/fingerprint.py's ``ALGORITHM_SIDE``) splits the runs of one algorithm only, so a
    comparison ranks each algorithm at its reference's settings. A trial without a fingerprint
    (recorded before there was one) stays with the task. ``env_split`` holds, per split trial, the
    fingerprint its label stands for (read by :func:`environment_note`)."""
    from lac_rllib.tasks.fingerprint import environment, fingerprint_id

    if not len(trials) or ENV_COLUMN not in trials:
        return trials
    trials = trials.copy()
    trials[ENV_SPLIT_COLUMN] = ""
    by = ["task", "algo"] if "algo" in trials else ["task"]
    for task, g in trials.groupby("task", sort=False):
        fps = {i: json.loads(j) if j else None for i, j in zip(g.index, g.get(ENV_JSON_COLUMN, [""] * len(g)))}
        known = [i for i in g.index if trials.at[i, ENV_COLUMN]]
        shared = {i: environment(fps[i]) if fps[i] else {"id": trials.at[i, ENV_COLUMN]} for i in known}
        if len({fingerprint_id(shared[i]) for i in known}) > 1:
            for i in known:
                trials.at[i, "task"] = f"{task}{ENV_LABEL}{fingerprint_id(shared[i])}"
                trials.at[i, ENV_SPLIT_COLUMN] = json.dumps(shared[i])
        for _, a in trials.loc[known].groupby(by, sort=False):
            if a[ENV_COLUMN].nunique() > 1:
                for i in a.index:
                    trials.at[i, "task"] = f"{task}{ENV_LABEL}{trials.at[i, ENV_COLUMN]}"
                    trials.at[i, ENV_SPLIT_COLUMN] = json.dumps(fps[i] or {"id": trials.at[i, ENV_COLUMN]})
    return trials


def environment_note(trials: pd.DataFrame) -> str:
    """One line per task split by :func:`split_environments`, naming what differs between its environments."""
    from lac_rllib.tasks.fingerprint import differences

    if not len(trials) or ENV_SPLIT_COLUMN not in trials:
        return ""
    split = trials[trials[ENV_SPLIT_COLUMN].astype(bool)]
    # The default configuration's environment first, then by trial id: the note reads "default vs
    # changed" and does not follow the order the trials happened to finish in (MLflow's run order).
    keys = [c for c in ("default", "trial_id") if c in split]
    if keys:
        split = split.sort_values(keys, ascending=[c != "default" for c in keys], kind="stable")
    lines = []
    for task, g in split.groupby(split["task"].astype(str).str.split(ENV_LABEL).str[0], sort=False):
        fps = {label.split(ENV_LABEL)[-1]: json.loads(j) for label, j in zip(g["task"], g[ENV_SPLIT_COLUMN])}
        ids = list(fps)
        diff = "; ".join(f"{a} vs {b}: {differences(fps[a], fps[b])}" for a, b in zip(ids, ids[1:]))
        lines.append(f"**Not ranked together**: `{task}` ran in {len(ids)} environments ({', '.join(ids)}), "
                     f"reported apart as `{task}{ENV_LABEL}ID`: {diff}.")
    return "\n".join(lines)


def scored(row: dict, curve, metrics: dict | None = None, kind: str = TRAIN) -> dict:
    """A trial's row ranked on its score (sweeps/score.py): episode return and cost those of the
    declared score ``kind`` (``eval``: the evaluation block's, read from the run's ``metrics``;
    ``train``: the means over its final 10% of iterations), feasibility and the objective from
    them; beside them both scores (``train_*``, ``eval_*``), the last iteration's values
    (``last_*``) and ``score``, the one used (``train`` where an eval score is missing). A trial
    with neither keeps its last values."""
    train, evaluated = train_score(curve), eval_score(metrics or {})
    (ret, cost), used = declared(kind, train, evaluated)
    out = {**row, LAST_RETURN: row[EPISODE_RETURN], LAST_COST: row[EPISODE_COST], TRAIN_RETURN: train[0],
           TRAIN_COST: train[1], EVAL_RETURN: evaluated[0], EVAL_COST: evaluated[1], "score": used}
    limit = row[COST_LIMIT]
    limits = constraint_limits(metrics or {})
    if len(limits) > 1:  # several constraints: the joint rule's cost max_k (J_k − b_k) against 0 (sweeps/score.py)
        (ret, cost), used, per = joint_score(kind, curve, metrics or {}, limits)
        # A rung of a ladder along constraint k: the same rule shifted by its limit b_k (cost b_k + the
        # excess against b_k), so the ladder's report ranks at each rung as at any limit. A frontier run
        # along k (its ν_k held; its b_k the ladder's top rung): J_k where every other constraint is
        # within its limit, else past the top rung by the others' excess (within no rung), so R*(b) is
        # the best return feasible at b on the joint rule.
        along = row.get("ladder_constraint") or ""
        limit = limits.get(along, 0.0)
        frontier = along in limits and row.get("group") == FRONTIER_GROUP

        def judged(costs: dict) -> float:
            if frontier:
                excess = max(costs[n] - b for n, b in limits.items() if n != along)
                return costs[along] if excess <= 0 else max(costs[along], limit + excess)
            return joint_cost(costs, limits) + limit

        cost = judged(per)
        # Both scores beside on the same rule (the summed costs kept as summed_*).
        (train_per, _), (eval_per, eval_used) = (constraint_scores(k, curve, metrics or {}, limits)
                                                 for k in (TRAIN, EVAL))
        out.update({"score": used, **{per_constraint(EPISODE_COST, n): c for n, c in per.items()},
                    **{per_constraint(COST_LIMIT, n): b for n, b in limits.items()}, COST_LIMIT: limit,
                    f"summed_{TRAIN_COST}": out[TRAIN_COST], f"summed_{EVAL_COST}": out[EVAL_COST],
                    TRAIN_COST: judged(train_per), EVAL_COST: judged(eval_per) if eval_used == EVAL else math.nan})
    if math.isnan(ret) or math.isnan(cost):
        return out
    return {**out, EPISODE_RETURN: ret, EPISODE_COST: cost, FEASIBLE: float(feasible(cost, limit)),
            OBJECTIVE: objective(ret, cost, limit)}


def varied(trials: pd.DataFrame, fields: tuple[str, ...]) -> list[str]:
    """The fields among ``fields`` whose value differs between the sweep's trials."""
    return [f for f in fields if f in trials and trials[f].astype(str).nunique() > 1]


def close_sweep(tracker: SweepTracker, parent: str, n_errors: int, heading: str, plan=None) -> None:
    """The report on the parent run (``summary/``) and the note that leads it; the parent closed."""
    from mlflow.entities import Metric

    from sweeps.reports.ladder import applies, by_limit, write_ladder_report
    from sweeps.reports.report import (
        algorithm_comparison,
        note_markdown,
        nothing_feasible_markdown,
        parent_metrics,
        summarize,
        write_sweep_reports,
    )
    from sweeps.reports.table import write_table_report

    # The table's budget: its env steps and what else it means (no plan: no table).
    budget_steps = plan.timesteps if plan is not None else None
    about_budget = budget_note(plan) if plan is not None else ""
    fields = swept_fields(plan) if plan is not None else ()
    trials, curves = sweep_results(tracker, parent, fields)
    note, ladder, ladder_metrics, table_note = heading, "", {}, ""
    with tempfile.TemporaryDirectory() as tmp:
        if len(trials):
            pareto = pareto_set(plan) if plan is not None and plan.sweep.multi_objective else None
            write_sweep_reports(trials, curves, tmp, fields=tuple(varied(trials, fields)))
            if applies(trials):  # a ladder of cost limits, or the fixed-multiplier frontier
                ladder, ladder_metrics = write_ladder_report(trials, tmp)
            if budget_steps:  # a sweep over tasks x algorithms: the paper's layout (None otherwise),
                for folder, rows in by_limit(trials):  # one table per limit of a ladder, the first leads
                    written = write_table_report(rows, Path(tmp) / folder, budget_steps, about_budget,
                                                 note_limit=5000)
                    table_note = table_note or (written[1] if written else "")
            if pareto is not None:
                (Path(tmp) / "pareto.json").write_text(json.dumps(pareto, indent=2, default=str))
        tracker.client.log_artifacts(parent, tmp, "summary")
        if len(trials):
            summary = summarize(trials)
            footer = ("Files: `summary/summary.md` (every column), `summary/table.md` and `table.html` (a sweep over "
                      "tasks x algorithms, in the paper's layout), `summary/frontier.html` (the reward-cost "
                      "frontier, interactive), `summary/importance.png`, `summary/aggregates.png`, "
                      "`summary/learning_curves.png`; one child run per trial (group them by the tag `lac.config` "
                      "in the runs table to see one averaged curve per configuration).")
            extra = note_extras(summary, trials, curves, fields, plan, pareto)
            note = note_markdown(summary, heading, footer, extra=extra)
            if ladder:  # the verdict across limits leads: one limit's ranking may not hold at another
                note = note.replace(heading, heading + "\n\n" + ladder, 1)[:7990]
            # The algorithms side by side lead the note (MLflow cuts a tag at 8000 characters): over
            # several tasks the table in the paper's layout, with the published figures; on one task
            # the comparison with LAC (P(LAC beats X); the table is in summary/table.md).
            several = trials["task"].nunique() > 1
            lead = (table_note if several else "") or algorithm_comparison(summary)
            if lead:
                note = note.replace(heading, heading + "\n\n" + lead, 1)[:7990]
            split = environment_note(trials)
            if split:  # said first: the tables below rank each environment apart
                note = note.replace(heading, heading + "\n\n" + split, 1)[:7990]
            nothing = nothing_feasible_markdown(summary)
            if nothing:  # said first, before any table (issue 36)
                note = note.replace(heading, heading + "\n\n" + nothing, 1)[:7990]
            # The runs table sorts and charts sweeps by these (docs/sweeps.md, "The parent run").
            metrics = {**parent_metrics(summary), **ladder_metrics}
            tracker.client.log_batch(parent, metrics=[Metric(k, v, int(time.time() * 1000), 0)
                                                      for k, v in metrics.items()])
    tracker.set_note(parent, note)
    tracker.client.set_tag(parent, "lac.failed_trials", str(n_errors))
    tracker.client.set_tag(parent, STATUS_TAG, "finished")
    tracker.client.set_terminated(parent, status="FINISHED")


def budget_note(plan) -> str:
    """What the table says of a named budget beside its env steps (a number of steps: nothing)."""
    from sweeps.spaces import BUDGETS

    budget = BUDGETS.get(plan.budget)
    return f"{plan.budget}: {budget.doc}" if budget is not None and plan.budget != "paper" else ""


def swept_fields(plan) -> tuple[str, ...]:
    """The fields a sweep varies (sweeps/reports/confirm.py ``varied_fields``) and ``algo``."""
    from sweeps.reports.confirm import varied_fields

    return tuple(dict.fromkeys([*varied_fields(plan.sweep), "algo"]))


def note_extras(summary, trials, curves, fields, plan, pareto) -> str:
    """What the note adds below its head: a confirmation's verdict, the Pareto set, the top three
    fields for return and cost, the safety statistics and chain-health flags."""
    from sweeps.reports import report

    parts = []
    if plan is not None and plan.confirms:
        from sweeps.reports.confirm import confirmation_markdown

        parts.append(confirmation_markdown(list(plan.confirms), summary, trials))
    if pareto:
        parts.append(report.pareto_markdown(pareto))
    parts.append(report.importance_markdown(trials, tuple(varied(trials, fields))))
    parts.append(report.safety_markdown(summary, trials, curves))
    parts.append(evaluation_share(trials))
    return "\n\n".join(p.strip() for p in parts if p)


def evaluation_share(trials: pd.DataFrame) -> str:
    """One line: what the evaluation blocks cost, their seconds against the trials' training
    seconds (those that ran one); "" when none did."""
    if EVAL_TIME_S not in trials or WALL_TIME_S not in trials:
        return ""
    ran = trials[pd.to_numeric(trials[EVAL_TIME_S], errors="coerce") > 0]
    if ran.empty:
        return ""
    spent, trained = (pd.to_numeric(ran[c], errors="coerce").sum() for c in (EVAL_TIME_S, WALL_TIME_S))
    share = spent / (spent + trained) if spent + trained > 0 else float("nan")
    return (f"Evaluation blocks: {spent / len(ran):.1f} s per trial on average, {share:.0%} of the "
            f"{len(ran)} trials' time (training {trained / len(ran):.1f} s per trial).")


def pareto_set(plan) -> list[dict] | None:
    """A multi-objective search's Pareto set from its Optuna study: the feasible non-dominated
    configurations on (return, cost), each with its sampled values."""
    import optuna

    try:
        study = optuna.load_study(study_name=plan.name, storage=plan.optuna_storage)
    except KeyError:
        return None
    return [{"number": t.number, "params": {k.split("/")[-1]: v for k, v in t.params.items()},
             EPISODE_RETURN: t.values[0], EPISODE_COST: t.values[1],
             "constraint": t.system_attrs.get(OPTUNA_CONSTRAINT_KEY)} for t in study.best_trials]

