"""What a sweep ranks a trial on, declared by the sweep file's ``score`` key (issue 36):

- ``eval`` (the default): the evaluation block at the trial's end (sweeps/trainable.py), the mean
  return and cost of ``eval_episodes`` episodes of the trained policy's deterministic action on
  env seeds no training episode used: the trained policy, not the exploring one;
- ``train``: the mean over the iterations in the final ``TAIL`` of the trial's env steps (those
  past (1 − TAIL) × its last env steps), as ``docs/fidelity/`` scores runs, at least the last
  iteration.

Never the last iteration alone: its return and cost are the mean over the few episodes the
stochastic policy completed in one iteration, one noisy sample of an exploring policy (Eimer et al.
2023, Hamilton et al. 2022 on single final samples). The reports, the objective and feasibility,
the frontier, the importances, the confirmation, the table and what Optuna is told all read the
declared score; the other score and the last iteration's values stay beside it (trials.csv,
summary.csv). A trial whose evaluation failed or did not run is scored on ``train`` and says so
(tag ``lac.score``; the reports count such trials).

With several constraints (a run's ``constraints``) a trial's score cost is the joint rule's,
max_k (J_k − b_k) over its constraints' costs J_k (the same score, train or eval, each) and limits
b_k, against a limit of 0: within exactly where every constraint is within its limit, so the one
feasibility rule (sweeps/objective.py) decides every verdict on the joint rule. Each constraint's
score cost stays beside it (``score_cost/NAME``, ``cost/NAME`` in trials.csv).
"""

from __future__ import annotations

import math

import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, ENV_STEPS, EPISODE_COST, EPISODE_RETURN, per_constraint

#: The fraction of a trial's env steps, at its end, whose iterations the train score averages.
TAIL = 0.10
EVAL, TRAIN = "eval", "train"
#: What the sweep file's ``score`` accepts (the first is the default).
SCORES = (EVAL, TRAIN)
#: The evaluation mode the eval score reads: the deterministic action (sweeps/trainable.py runs it first).
EVAL_MODE = "generator"
#: The evaluation block's metrics the eval score reads (sweeps/evaluate.py logs them).
EVAL_RETURN_KEY, EVAL_COST_KEY = f"eval/{EVAL_MODE}/return_mean", f"eval/{EVAL_MODE}/cost_mean"
#: The final-iteration values a trial keeps beside its score (trials.csv, summary).
LAST_RETURN, LAST_COST = "last_return", "last_cost"
#: Each score's return and cost, kept beside the declared one (trials.csv, summary.csv, the trial's run).
TRAIN_RETURN, TRAIN_COST = "train_return", "train_cost"
EVAL_RETURN, EVAL_COST = "eval_return", "eval_cost"
#: What a finished trial logs and reports as its declared score (MLflow metrics, Tune's last result).
SCORE_RETURN, SCORE_COST = "score_return", "score_cost"
#: The tag a trial's run carries: the score it was ranked on (``eval`` or ``train``).
SCORE_TAG = "lac.score"


def description(kind: str, fallbacks: int = 0) -> str:
    """How the reports say what they rank on (``kind``: the declared score; ``fallbacks``: trials
    whose evaluation was missing, scored on ``train``)."""
    train = f"the mean of its episode return and cost over the iterations in its final {TAIL:.0%} of env steps"
    if kind == EVAL:
        text = (f"each trial's score is its evaluation block's (`score: eval`): the mean return and cost of its "
                f"trained policy's deterministic action over held-out episodes (the training score, {train}: "
                f"`{TRAIN_RETURN}`, `{TRAIN_COST}` in trials.csv and summary.csv)")
        if fallbacks:
            text += f"; {fallbacks} trial(s) without an evaluation are scored on training"
        return text
    return (f"each trial's score is {train} (`score: train`; the evaluation block's: `{EVAL_RETURN}`, "
            f"`{EVAL_COST}`; the last iteration's alone: `{LAST_RETURN}`, `{LAST_COST}` in trials.csv)")


def described(used) -> str:
    """:func:`description` for trials whose used scores are ``used`` (``eval`` / ``train`` each):
    the eval score's when any trial was ranked on it, with the others counted."""
    used = [u for u in used if isinstance(u, str)]
    n_eval = sum(u == EVAL for u in used)
    return description(EVAL, len(used) - n_eval) if n_eval else description(TRAIN)


def train_score(curve: pd.DataFrame | None) -> tuple[float, float]:
    """(return, cost) of a learning curve (env_steps, episode_return, episode_cost per iteration):
    their means over the iterations past (1 − TAIL) × the last env steps; NaN without iterations."""
    if curve is None or not len(curve) or ENV_STEPS not in curve:
        return math.nan, math.nan
    steps = pd.to_numeric(curve[ENV_STEPS], errors="coerce")
    tail = curve[steps > (1 - TAIL) * steps.max()]
    if tail.empty:  # one iteration, or steps unknown: the last iteration
        tail = curve.tail(1)
    return (float(pd.to_numeric(tail[EPISODE_RETURN], errors="coerce").mean()),
            float(pd.to_numeric(tail[EPISODE_COST], errors="coerce").mean()))


def eval_score(metrics: dict) -> tuple[float, float]:
    """(return, cost) of the evaluation block's deterministic episodes in a run's ``metrics``; NaN
    where the block did not run or failed."""
    ret, cost = metrics.get(EVAL_RETURN_KEY), metrics.get(EVAL_COST_KEY)
    if ret is None or cost is None:
        return math.nan, math.nan
    return float(ret), float(cost)


def declared(kind: str, train: tuple[float, float], evaluated: tuple[float, float]) -> tuple[tuple[float, float], str]:
    """((return, cost), the score used): the declared ``kind``'s, or ``train`` where an eval score
    is asked and missing."""
    if kind == EVAL and all(math.isfinite(v) for v in evaluated):
        return evaluated, EVAL
    return train, TRAIN


def constraint_limits(metrics: dict) -> dict[str, float]:
    """name → b of a run with several constraints, read from its metrics (``cost_limit/NAME``, every
    iteration's row logs them); empty for a run with one constraint."""
    prefix = f"{COST_LIMIT}/"
    return {k[len(prefix):]: float(v) for k, v in sorted(metrics.items()) if k.startswith(prefix)}


def constraint_scores(kind: str, curve: pd.DataFrame | None, metrics: dict, limits: dict[str, float]
                      ) -> tuple[dict[str, float], str]:
    """(name → the constraint's score cost, the score used): each constraint's eval cost
    (``eval/generator/cost_mean/NAME``) where ``kind`` is eval and every one is there, else its train
    cost (the tail mean of its ``episode_cost/NAME`` curve)."""
    evaluated = {n: metrics.get(per_constraint(EVAL_COST_KEY, n)) for n in limits}
    if kind == EVAL and all(v is not None and math.isfinite(v) for v in evaluated.values()):
        return {n: float(v) for n, v in evaluated.items()}, EVAL
    out = {}
    for name in limits:
        column = per_constraint(EPISODE_COST, name)
        if curve is None or column not in curve or not len(curve):
            out[name] = math.nan
            continue
        out[name] = train_score(curve.rename(columns={EPISODE_COST: "_summed", column: EPISODE_COST}))[1]
    return out, TRAIN


def joint_cost(costs: dict[str, float], limits: dict[str, float]) -> float:
    """The joint rule's cost max_k (J_k − b_k), to be held to a limit of 0 (NaN if any J_k is)."""
    excess = [costs[n] - b for n, b in limits.items()]
    return math.nan if any(math.isnan(e) for e in excess) else max(excess)


def joint_score(kind: str, curve: pd.DataFrame | None, metrics: dict, limits: dict[str, float]
                ) -> tuple[tuple[float, float], str, dict[str, float]]:
    """A trial with several constraints: ((return, joint cost), the score used, name → its cost),
    return and costs from the same score (eval where every one of them is there, else train)."""
    train, evaluated = train_score(curve), eval_score(metrics)
    (ret, _), used = declared(kind, train, evaluated)
    per, used_costs = constraint_scores(used, curve, metrics, limits)
    if used_costs != used:  # an eval return without every constraint's eval cost: all on train
        ret, used = train[0], TRAIN
    return (ret, joint_cost(per, limits)), used, per


def row_cost(row: dict) -> tuple[float, float]:
    """(cost, limit) an iteration's row is judged by: its episode cost and limit, or with several
    constraints the joint rule's max_k (J_k − b_k) and 0 (``episode_cost/NAME``, ``cost_limit/NAME``)."""
    limits = constraint_limits(row)
    if len(limits) < 2:
        return row[EPISODE_COST], row[COST_LIMIT]
    return joint_cost({n: row.get(per_constraint(EPISODE_COST, n), math.nan) for n in limits}, limits), 0.0


def joint_curve(curve: pd.DataFrame | None, limits: dict[str, float], along: str | None = None
                ) -> pd.DataFrame | None:
    """A learning curve with several constraints judged as the verdicts judge it: its episode cost the
    joint rule's max_k (J_k − b_k) per iteration and its limit 0 (the summed cost kept as
    ``summed_cost``), so every figure read from a curve (violation, steps to feasible, the multiplier's
    behaviour) reads the joint rule; on a rung of a ladder ``along`` constraint k both shifted by b_k.
    A curve without the constraints' columns is returned as it is."""
    if curve is None or len(limits) < 2 or any(per_constraint(EPISODE_COST, n) not in curve for n in limits):
        return curve
    excess = pd.concat([pd.to_numeric(curve[per_constraint(EPISODE_COST, n)], errors="coerce") - b
                        for n, b in limits.items()], axis=1).max(axis=1, skipna=False)
    shift = limits.get(along or "", 0.0)
    return curve.assign(summed_cost=curve[EPISODE_COST], **{EPISODE_COST: excess + shift, COST_LIMIT: shift})
