"""The score a sweep ranks a trial on (sweeps/score.py): its final 10% of iterations, not the last."""

import math

import pandas as pd
import pytest

from sweeps import score
from sweeps.reports.results import scored


def _curve(costs, returns=None, step=1000):
    returns = returns or [1.0] * len(costs)
    return pd.DataFrame({"env_steps": [step * (i + 1) for i in range(len(costs))], "episode_return": returns,
                         "episode_cost": costs, "cost_limit": 25.0})


def test_the_score_is_the_mean_over_the_final_tenth_of_the_env_steps():
    # 20 iterations of 1000 steps: the final 10% are the iterations past 18,000 steps: the last two.
    costs = [40.0] * 18 + [20.0, 30.0]
    ret, cost = score.train_score(_curve(costs, returns=list(range(20))))
    assert (ret, cost) == (pytest.approx(18.5), pytest.approx(25.0))
    assert score.train_score(_curve([7.0], returns=[3.0])) == (3.0, 7.0)  # one iteration: itself
    assert all(math.isnan(x) for x in score.train_score(None))


def test_a_trial_whose_last_iteration_is_infeasible_ranks_as_its_final_tenth_says():
    """Its last iteration is over the limit (30 > 25), its final 10% within (mean 24): feasible,
    with the objective of its score; the last values are kept beside it."""
    row = {"episode_return": 9.0, "episode_cost": 30.0, "cost_limit": 25.0, "feasible": 0.0, "objective": -1e6 - 5}
    curve = _curve([40.0] * 18 + [18.0, 30.0], returns=[1.0] * 18 + [11.0, 9.0])
    out = scored(row, curve)
    assert (out["episode_return"], out["episode_cost"], out["feasible"]) == (10.0, 24.0, 1.0)
    assert out["objective"] == 10.0 and (out["last_return"], out["last_cost"]) == (9.0, 30.0)
    # And the other way round: a last iteration within the limit after a final 10% over it.
    worse = scored({**row, "episode_cost": 20.0, "feasible": 1.0, "objective": 9.0},
                   _curve([0.0] * 18 + [40.0, 20.0]))
    assert worse["feasible"] == 0.0 and worse["objective"] == pytest.approx(-1e6 - 5.0)
    # No curve: the last values stand.
    assert scored(row, None)["episode_cost"] == 30.0


def test_under_score_eval_a_trial_ranks_on_its_evaluation_and_under_train_on_its_final_tenth():
    """Its last iteration is infeasible (30 > 25) and so is its final 10% (mean 35); its evaluation
    block is feasible (12): feasible under ``score: eval``, infeasible under ``score: train``, each
    with the other score kept beside it."""
    row = {"episode_return": 9.0, "episode_cost": 30.0, "cost_limit": 25.0, "feasible": 0.0, "objective": -1e6 - 5}
    curve = _curve([10.0] * 18 + [40.0, 30.0], returns=[1.0] * 18 + [11.0, 9.0])
    metrics = {score.EVAL_RETURN_KEY: 14.0, score.EVAL_COST_KEY: 12.0}
    by_eval = scored(row, curve, metrics, score.EVAL)
    assert (by_eval["episode_return"], by_eval["episode_cost"], by_eval["feasible"]) == (14.0, 12.0, 1.0)
    assert by_eval["objective"] == 14.0 and by_eval["score"] == "eval"
    assert (by_eval["train_return"], by_eval["train_cost"]) == (10.0, 35.0)
    by_train = scored(row, curve, metrics, score.TRAIN)
    assert (by_train["episode_cost"], by_train["feasible"], by_train["score"]) == (35.0, 0.0, "train")
    assert by_train["objective"] < -1e5 and (by_train["eval_return"], by_train["eval_cost"]) == (14.0, 12.0)
    # An eval score asked for and missing (the block failed or did not run): train, and it says so.
    missing = scored(row, curve, {}, score.EVAL)
    assert (missing["episode_cost"], missing["score"]) == (35.0, "train") and math.isnan(missing["eval_cost"])
    assert "1 trial(s) without an evaluation" in score.described(["eval", "train", "eval"])
    assert "score: train" in score.described(["train", "train"])


def test_score_eval_without_evaluation_episodes_is_refused_and_no_score_then_means_train():
    from sweeps import sweep_file

    with pytest.raises(Exception, match="score eval ranks on the evaluation block"):
        sweep_file.SweepFile.model_validate({"score": "eval", "eval_episodes": 0})
    with pytest.raises(Exception, match="eval.*train"):
        sweep_file.SweepFile.model_validate({"score": "last"})


def test_with_several_constraints_a_trial_is_judged_on_the_joint_rule():
    """hazard ≤ 2 and lane ≤ 10: a trial at hazard 0, lane 11 has a summed cost of 11 under the limits'
    sum 12, and breaks the lane: infeasible, its cost the joint rule's max_k (J_k − b_k) = 1 against
    0. Its evaluation block within both (1, 9): feasible under score eval, cost −1."""
    limits = {"cost_limit/hazard": 2.0, "cost_limit/lane": 10.0}
    curve = _curve([11.0] * 20)
    curve["episode_cost/hazard"], curve["episode_cost/lane"] = 0.0, 11.0
    row = {"episode_return": 9.0, "episode_cost": 11.0, "cost_limit": 12.0, "feasible": 1.0, "objective": 9.0}
    by_train = scored(row, curve, dict(limits), score.TRAIN)
    assert (by_train["episode_cost"], by_train["cost_limit"], by_train["feasible"]) == (1.0, 0.0, 0.0)
    assert (by_train["episode_cost/hazard"], by_train["episode_cost/lane"]) == (0.0, 11.0)
    assert by_train["objective"] == pytest.approx(-1e6 - 1.0)
    evaluated = {**limits, score.EVAL_RETURN_KEY: 5.0, score.EVAL_COST_KEY: 10.0,
                 "eval/generator/cost_mean/hazard": 1.0, "eval/generator/cost_mean/lane": 9.0}
    by_eval = scored(row, curve, evaluated, score.EVAL)
    assert (by_eval["episode_cost"], by_eval["feasible"], by_eval["score"]) == (-1.0, 1.0, "eval")
    assert by_eval["objective"] == 5.0
    # One constraint's eval cost missing: return and costs both from training, and it says so.
    partial = scored(row, curve, {k: v for k, v in evaluated.items() if k != "eval/generator/cost_mean/lane"},
                     score.EVAL)
    assert (partial["score"], partial["episode_return"], partial["episode_cost"]) == ("train", 1.0, 1.0)
    # An iteration's row: the same rule.
    assert score.row_cost({"episode_cost": 11.0, "cost_limit": 12.0, **limits, "episode_cost/hazard": 0.0,
                           "episode_cost/lane": 11.0}) == (1.0, 0.0)
    assert score.row_cost({"episode_cost": 11.0, "cost_limit": 12.0}) == (11.0, 12.0)


def test_the_summary_says_what_the_cost_is_with_several_constraints():
    from sweeps.reports.report import constraints_note

    two = pd.DataFrame({"episode_cost": [1.0], "cost_limit/hazard": [2.0], "cost_limit/lane": [10.0]})
    assert "Several constraints (hazard, lane): a trial's cost is the joint rule's" in constraints_note(two)
    assert constraints_note(pd.DataFrame({"episode_cost": [1.0], "cost_limit": [25.0]})) == ""


def test_a_curve_with_several_constraints_is_judged_on_the_joint_rule():
    from sweeps.reports.multiplier import constraint_behaviour
    from sweeps.reports.safety import violation

    curve = _curve([5.0, 5.0, 5.0])
    curve["episode_cost/hazard"], curve["episode_cost/lane"] = [3.0, 1.0, 1.0], [2.0, 12.0, 9.0]
    curve["nu/hazard"], curve["nu/lane"] = [0.1, 0.0, 0.0], [0.0, 0.2, 0.3]
    limits = {"hazard": 2.0, "lane": 10.0}
    joint = score.joint_curve(curve, limits)
    assert joint["episode_cost"].tolist() == [1.0, 2.0, -1.0] and (joint["cost_limit"] == 0.0).all()
    assert joint["summed_cost"].tolist() == [5.0, 5.0, 5.0]
    assert violation(joint)["steps_to_feasible"] == 3000  # summed 5 ≤ 25 would say 1000
    assert score.joint_curve(curve, {"hazard": 2.0}) is curve  # one constraint: as it is
    figures = constraint_behaviour(curve, limits)
    assert figures["steps_to_feasible/hazard"] == 2000 and figures["steps_to_feasible/lane"] == 1000
    assert figures["nu_at_zero/hazard"] == pytest.approx(2 / 3)


def test_a_rung_of_a_ladder_along_one_constraint_is_the_joint_rule_shifted_to_its_limit():
    limits = {"cost_limit/hazard": 2.0, "cost_limit/lane": 10.0}
    curve = _curve([11.0] * 20)
    curve["episode_cost/hazard"], curve["episode_cost/lane"] = 1.0, 11.0
    row = {"episode_return": 9.0, "episode_cost": 11.0, "cost_limit": 12.0, "feasible": 1.0, "objective": 9.0,
           "ladder_constraint": "lane"}
    out = scored(row, curve, dict(limits), score.TRAIN)
    assert (out["episode_cost"], out["cost_limit"], out["feasible"]) == (11.0, 10.0, 0.0)  # 10 + excess 1
    assert out["objective"] == pytest.approx(-1e6 - 1.0)  # the same as on the unshifted rule
    shifted = score.joint_curve(curve, {"hazard": 2.0, "lane": 10.0}, along="lane")
    assert (shifted["episode_cost"] == 11.0).all() and (shifted["cost_limit"] == 10.0).all()


def test_the_summary_says_a_ladder_along_a_constraint_is_shifted():
    from sweeps.reports.report import constraints_note

    two = pd.DataFrame({"cost_limit/hazard": [2.0], "cost_limit/lane": [10.0], "ladder_constraint": ["lane"]})
    assert "On the ladder along lane both are shifted by the rung's limit b" in constraints_note(two)


def test_a_frontier_run_along_a_constraint_is_that_constraints_cost_where_the_others_hold():
    limits = {"cost_limit/hazard": 2.0, "cost_limit/lane": 20.0}
    curve = _curve([7.0] * 20)
    curve["episode_cost/hazard"], curve["episode_cost/lane"] = 1.0, 6.0
    row = {"episode_return": 9.0, "episode_cost": 7.0, "cost_limit": 22.0, "feasible": 1.0, "objective": 9.0,
           "ladder_constraint": "lane", "group": "frontier"}
    assert scored(row, curve, dict(limits), score.TRAIN)["episode_cost"] == 6.0  # J_lane: feasible at b >= 6
    curve["episode_cost/hazard"] = 3.0  # the hazard over its limit by 1: past the top rung (20) by 1
    assert scored(row, curve, dict(limits), score.TRAIN)["episode_cost"] == 21.0


def test_with_several_constraints_both_scores_beside_read_the_joint_rule():
    limits = {"cost_limit/hazard": 2.0, "cost_limit/lane": 10.0}
    curve = _curve([11.0] * 20)
    curve["episode_cost/hazard"], curve["episode_cost/lane"] = 0.0, 11.0
    row = {"episode_return": 9.0, "episode_cost": 11.0, "cost_limit": 12.0, "feasible": 1.0, "objective": 9.0}
    evaluated = {**limits, score.EVAL_RETURN_KEY: 5.0, score.EVAL_COST_KEY: 10.0,
                 "eval/generator/cost_mean/hazard": 1.0, "eval/generator/cost_mean/lane": 9.0}
    out = scored(row, curve, evaluated, score.EVAL)
    assert (out["train_cost"], out["eval_cost"]) == (1.0, -1.0)  # the joint rule's, as the score
    assert (out["summed_train_cost"], out["summed_eval_cost"]) == (11.0, 10.0)
    assert math.isnan(scored(row, curve, dict(limits), score.TRAIN)["eval_cost"])
