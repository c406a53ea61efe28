"""The live table's rows and its progress line (Tune's trials faked: only what the reporter reads)."""

from sweeps.live_table import LiveTable, progress_line


class FakeTrial:
    def __init__(self, label, status, result=None):
        self.label, self.status, self.last_result = label, status, result or {}

    def __str__(self):
        return self.label


def _result(it, steps, ret, cost, feasible, nu, t):
    return {"training_iteration": it, "env_steps": float(steps), "episode_return": ret, "episode_cost": cost,
            "feasible": float(feasible), "nu": nu, "time_total_s": float(t)}


def test_the_eta_comes_from_the_finished_trials():
    trials = [FakeTrial("a", "TERMINATED", _result(4, 2000, 1.0, 0.0, 1, 0.1, 60)),
              FakeTrial("b", "TERMINATED", _result(4, 2000, 1.0, 0.0, 1, 0.1, 120)),
              FakeTrial("c", "RUNNING", _result(1, 500, 1.0, 0.0, 1, 0.1, 30)),
              FakeTrial("d", "ERROR", _result(1, 500, 1.0, 0.0, 1, 0.1, 5))]
    # mean 90 s over the two that finished; 6 - 3 done - 1 running = 2 not started, and the running
    # one owes 60 s: (2 * 90 + 60) / 2 slots = 120 s.
    assert progress_line(trials, total=6, concurrency=2) == (
        "progress: 3/6 trials done (1 failed) · 1 running · ETA ~2 min (mean 1.5 min per finished trial, n=2)")
    assert progress_line(trials[2:3], total=6, concurrency=2).endswith("ETA after the first trial finishes")


def test_rows_say_what_each_trial_is_running_first_and_cut_when_long():
    trials = [FakeTrial(f"VT-langevin_steps={t}-PointHazard-v0-s0", "TERMINATED",
                        _result(40, 40000, -1.25, 3.0, 0, 0.25, 90)) for t in (10, 20)]
    running = _result(3, 3000, -9.5, 0.0, 1, 0.0, 9)
    trials.append(FakeTrial("NI-langevin_steps=500-PointHazard-v0-s2", "RUNNING", running))
    trials.append(FakeTrial("PR-beta=20.0-PointHazard-v0-s2", "PENDING"))
    lines = LiveTable(total=4, concurrency=2, max_rows=3).render(trials, done=False).splitlines()
    assert lines[0].split() == ["trial", "status", "iter", "env", "steps", "return", "cost", "feasible", "ν"]
    assert lines[1].split() == ["NI-langevin_steps=500-PointHazard-v0-s2", "RUNNING", "3", "3,000", "-9.50", "0.0",
                                "yes", "0.000"]
    assert lines[2].split() == ["VT-langevin_steps=10-PointHazard-v0-s0", "TERMINATED", "40", "40,000", "-1.25",
                                "3.0", "no", "0.250"]
    assert lines[4] == "… 1 more trials not shown" and lines[5].startswith("progress: 2/4 trials done")
    assert len(LiveTable(4, 2, max_rows=3).render(trials, done=True).splitlines()) == 6  # all rows at the end


def test_with_several_constraints_the_cost_column_shows_the_worst_one():
    from sweeps.live_table import cost_cell, trial_row

    r = {**_result(3, 1500, 1.0, 13.0, 0, 0.4, 30), "cost_limit": 12.0, "cost_limit/hazard": 2.0,
         "cost_limit/lane": 10.0, "episode_cost/hazard": 2.5, "episode_cost/lane": 10.5}
    assert cost_cell(r) == "hazard 2.5/2"  # excess 0.5 each: the first of the task's order wins a tie
    r["episode_cost/lane"] = 11.0
    assert trial_row(FakeTrial("t", "RUNNING", r))[5] == "lane 11.0/10"
    assert cost_cell(_result(3, 1500, 1.0, 13.0, 0, 0.4, 30)) == "13.0"
