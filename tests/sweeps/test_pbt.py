"""Population-based training that respects the constraint (sweeps/pbt.py): the exploit's copy, the
ranking, the bounds, the replay of a winner's schedule, kill and resume, and what is refused."""

import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from sweeps import run as cli
from sweeps.objective import OBJECTIVE_WINDOW, objective
from sweeps.pbt import ConstrainedPBT, clip_to_bounds, fields_at, subpopulations, window_row
from sweeps.score import row_cost

REPO = Path(__file__).resolve().parents[2]
TASK = "lac/PointHazard-v0"

PBT_FILE = """task: lac/PointHazard-v0
algo: ppo_lag
budget: smoke
search: pbt
eval_episodes: 0
pbt: {members: 4, interval: 1000, window: 2}
"""


# ----------------------------------------------------------------------------- the exploit's copy

def _flat(d, path=""):
    if isinstance(d, dict):
        return {k: v for key, value in d.items() for k, v in _flat(value, f"{path}/{key}").items()}
    if isinstance(d, (list, tuple)):
        return {k: v for i, value in enumerate(d) for k, v in _flat(value, f"{path}[{i}]").items()}
    return {path: d}


def _differences(a: dict, b: dict) -> list[str]:
    out = []
    for k in sorted(set(a) | set(b)):
        if k not in a or k not in b:
            out.append(k)
            continue
        x, y = a[k], b[k]
        try:
            same = np.array_equal(np.asarray(x), np.asarray(y), equal_nan=np.asarray(x).dtype.kind == "f")
        except (TypeError, ValueError):
            same = x == y
        if not same:
            out.append(k)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo_lag", "sac_lag", "lac"])
def test_an_exploit_copies_the_whole_learner_bit_for_bit_and_keeps_the_members_own_rates(ray_session, algo):
    """The member rebuilt with perturbed fields and the donor's checkpoint restored into it equals
    the donor bit for bit (weights, targets, every optimizer's moments and step, each multiplier
    and its rule's state, the observation filter, the replay buffer), its learning rates aside:
    they are the member's own. Without lac_rllib/constrained/changeable.py they are the donor's."""
    from lac_rllib.algorithms.registry import algo_config, build_config, split_algo
    from lac_rllib.constrained.changeable import optimizer_lrs, reapply_learning_rates
    from sweeps.spaces import trial_params

    name, fields = split_algo(trial_params(TASK, "smoke", {"algo": algo}))
    changeable = algo_config(name).changeable_fields()
    perturbed = {f: fields[f] * 1.2 for f in changeable if isinstance(fields[f], float)}
    assert any(f.endswith("lr") for f in perturbed), perturbed

    def build(own):
        return build_config(name, TASK, 0, {**own, "torch_threads": 1}, timesteps=2000, cpus=1).build_algo()

    donor = build(fields)
    member = unfixed = None
    try:
        for _ in range(2):
            donor.train()
        with tempfile.TemporaryDirectory() as tmp:
            donor.save_to_path(tmp)
            before = _flat(donor.get_state())
            member, unfixed = build({**fields, **perturbed}), build({**fields, **perturbed})
            for copy in (member, unfixed):
                copy.restore_from_path(tmp)
            reapply_learning_rates(member)
        after = _flat(member.get_state())
        lr_keys = {k for k in before if k.endswith("/lr") and "param_groups" in k}
        assert lr_keys, "the optimizers' state carries their lr"
        assert _differences(before, after) == sorted(k for k in lr_keys if _differences(
            {k: before[k]}, {k: after[k]})), "only the learning rates differ from the donor"
        # What was copied is there: the multiplier's ν and the filter's statistics are not empty.
        assert any("nu" in k for k in after)
        if fields.get("obs_normalization"):
            assert any("filter" in k.lower() for k in after), "the observation filter's statistics"
        if algo in ("sac_lag", "lac"):
            assert any("replay_buffer" in k for k in after), "the replay buffer travels with the learner"
        mine, theirs, stale = optimizer_lrs(member)[0], optimizer_lrs(donor)[0], optimizer_lrs(unfixed)[0]
        assert stale == theirs, "RLlib's restore hands the member the donor's learning rates"
        assert mine != theirs
        for opt, lr in mine.items():  # each the member's own field (×1.2 of the donor's, or unchanged)
            assert lr == pytest.approx(theirs[opt] * 1.2) or lr == pytest.approx(theirs[opt])
        assert any(lr == pytest.approx(theirs[o] * 1.2) for o, lr in mine.items())
        # The multiplier's rate is the member's: it is not in the state (LagrangeMultiplier.get_state).
        if "lagrangian_lr" in perturbed:
            rates = member.learner_group.foreach_learner(
                lambda learner: sorted({round(m.rule.lr, 12) for m in _rules(learner)}))
            assert [r.get() for r in rates][0] == [round(perturbed["lagrangian_lr"], 12)]
    finally:
        for a in (donor, member, unfixed):
            if a is not None:
                a.stop()


def _rules(learner):
    from lac_rllib.constrained.lagrange import each_multiplier

    return [p for m in learner.multipliers.values() for p in each_multiplier(m) if hasattr(p.rule, "lr")]


# ----------------------------------------------------------------------------- ranking and bounds

class _Trial:
    def __init__(self, index):
        self.config, self.trial_id, self.experiment_tag = {"__trial_index__": index}, f"t{index}", str(index)

    def is_finished(self):
        return False


def _scheduler(intervals=(1000,), seed=0):
    return ConstrainedPBT(time_attr="env_steps", metric=OBJECTIVE_WINDOW, mode="max", intervals=intervals,
                          mutations={"lr": [1e-3]}, bounds={}, seed=seed)


def test_a_feasible_low_return_member_outranks_an_infeasible_high_return_one():
    from ray.tune.schedulers.pbt import _PBTTrialState

    def windowed(rows):
        mean = window_row(rows)
        return objective(mean["episode_return"], *row_cost(mean))

    rows = {  # (return, cost) over the last iterations, limit 10
        "feasible-low": [(1.0, 9.0), (2.0, 10.0)],
        "infeasible-high": [(50.0, 12.0), (60.0, 11.0)],
        "barely-over-once": [(30.0, 4.0), (30.0, 12.0)],  # one noisy iteration over: its window is within
        "far-over": [(70.0, 40.0), (80.0, 30.0)],
    }
    scores = {k: windowed([{"episode_return": r, "episode_cost": c, "cost_limit": 10.0} for r, c in v])
              for k, v in rows.items()}
    assert scores["barely-over-once"] > scores["feasible-low"] > scores["infeasible-high"] > scores["far-over"]
    # Several constraints: the joint rule on each constraint's window mean.
    two = [{"episode_return": 5.0, "episode_cost": 3.0, "episode_cost/a": 1.0, "episode_cost/b": 2.0,
            "cost_limit/a": 1.5, "cost_limit/b": 1.0}, {"episode_return": 7.0, "episode_cost": 1.0,
                                                         "episode_cost/a": 1.0, "episode_cost/b": 0.0,
                                                         "cost_limit/a": 1.5, "cost_limit/b": 1.0}]
    assert row_cost(window_row(two)) == (0.0, 0.0)  # b's mean 1.0 meets 1.0; a's 1.0 under 1.5
    scheduler = _scheduler()
    trials = {k: _Trial(i) for i, k in enumerate(scores)}
    for k, t in trials.items():
        scheduler._trial_state[t] = _PBTTrialState(t)
        scheduler._trial_state[t].last_score = scores[k]
    bottom, top = scheduler._quantiles()
    assert bottom == [trials["far-over"]] and top == [trials["barely-over-once"]]


def test_perturbations_never_leave_the_declared_bounds():
    from sweeps.sweep import pbt_bounds, pbt_mutations
    from sweeps.sweep_file import Distribution

    search = {"lr": Distribution(loguniform=[1e-4, 1e-2]), "langevin_steps": Distribution(int=[10, 100]),
              "beta": Distribution(choice=[0.0, 1.0, 5.0])}
    scheduler = ConstrainedPBT(time_attr="env_steps", metric=OBJECTIVE_WINDOW, mode="max", intervals=(1000,),
                               mutations=pbt_mutations(search), bounds=pbt_bounds(search), seed=0,
                               resample_probability=0.25)
    donor = _Trial(0)
    escaped = 0
    for start in ({"lr": 1e-2, "langevin_steps": 100, "beta": 5.0}, {"lr": 1e-4, "langevin_steps": 10, "beta": 0.0}):
        donor.config = {"__trial_index__": 0, "overrides": dict(start)}
        for _ in range(200):
            with scheduler._own_random():
                new, _ = scheduler._get_new_config(None, donor)
            o = new["overrides"]
            assert 1e-4 <= o["lr"] <= 1e-2 and 10 <= o["langevin_steps"] <= 100 and o["beta"] in (0.0, 1.0, 5.0)
            assert isinstance(o["langevin_steps"], int)
            # Tune's own explore from the same edge leaves the range (ray-project/ray#5035).
            from ray.tune.schedulers.pbt import _explore

            raw, _ = _explore(donor.config, scheduler._hyperparam_mutations, 0.0, (1.2, 0.8), None)
            escaped += not (1e-4 <= raw["overrides"]["lr"] <= 1e-2)
    assert escaped > 50
    assert clip_to_bounds({"overrides": {"lr": 0.5}}, {"lr": ("loguniform", 1e-4, 1e-2)})["overrides"]["lr"] == 1e-2


def test_the_scheduler_draws_on_its_own_seeded_random_stream():
    def draws(seed):
        s = _scheduler(seed=seed)
        random.seed(123)
        with s._own_random():
            out = [random.random() for _ in range(3)]
        return out, random.random()

    (a, outer_a), (b, outer_b), (c, _) = draws(1), draws(1), draws(2)
    assert a == b and a != c
    random.seed(123)
    assert outer_a == outer_b == random.random(), "the process's own stream is left where it was"


def test_sub_populations_and_schedules():
    assert subpopulations(6, (1000, 4000)) == [0, 1, 0, 1, 0, 1]
    s = _scheduler(intervals=(1000, 4000))
    assert [s.subpop(_Trial(i)) for i in range(4)] == [0, 1, 0, 1]
    schedule = [[0, {"lr": 1.0, "clip_param": 0.2}], [1500, {"lr": 2.0, "clip_param": 0.2}]]
    assert fields_at(schedule, 0) == {"lr": 1.0, "clip_param": 0.2}
    assert fields_at(schedule, 1499)["lr"] == 1.0 and fields_at(schedule, 1500)["lr"] == 2.0
    assert fields_at([], 10_000) == {}


# ----------------------------------------------------------------------------- refused before Ray

def _refused(tmp_path, text, needle, monkeypatch, capsys, *extra):
    import ray

    (tmp_path / "pbt.yaml").write_text(text)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(ray, "init", lambda *a, **k: pytest.fail("Ray was started for a bad input"))
    try:
        rc = cli.main(["--config", str(tmp_path / "pbt.yaml"), *extra])
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2 and needle in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "ray_results").exists()


@pytest.mark.parametrize("change, needle", [
    ("search:\n  lr: {loguniform: [1.0e-4, 1.0e-2]}\n  num_envs_per_env_runner: {int: [1, 4]}\nsearcher: pbt\n",
     "num_envs_per_env_runner is not a field ppo_lag can change mid-run; accepted with searcher pbt: lr, "),
    ("search: pbt\npbt: {members: 1}\n", "members"),
    ("search: pbt\npbt: {members: 4, interval: 2000}\n", "2,000 env steps is not shorter than the budget"),
    ("search: pbt\npbt: {members: 3, interval: [500, 1000]}\n",
     "each needs two members to rank; accepted: members >= 4"),
    ("searcher: pbt\ngrid: {lr: [0.001, 0.002]}\n", "searcher pbt with grid"),
    ("search: pbt\nscheduler: asha\n", "scheduler with searcher pbt"),
    ("search: pbt\nseeds: 3\npbt: {members: 4}\n", "3 seeds with pbt.members 4"),
    ("search: default\npbt: {members: 4}\n", "pbt with searcher unset: it configures population-based training"),
    ("groups:\n  g:\n    schedule: [{at: 0, set: {lr: 0.001}}, {at: 500, set: {hidden: [8, 8]}}]\n",
     "hidden is not a field ppo_lag can change mid-run; accepted in a schedule: lr, "),
    ("groups:\n  g:\n    schedule: [{at: 500, set: {lr: 0.001}}, {at: 500, set: {lr: 0.002}}]\n",
     "strictly ascending"),
    ("search: pbt\nenv_steps_budget: 100000\n", "env_steps_budget without a sampling search"),
    ("search: default\nseeds: 2\nenv_steps_budget: 3000\n",
     "3,000 is less than one configuration costs (2 seeds × 2,000 env steps); accepted: at least 4,000"),
])
def test_bad_pbt_input_is_refused_before_ray_in_one_line(tmp_path, monkeypatch, capsys, change, needle):
    _refused(tmp_path, "task: lac/PointHazard-v0\nalgo: ppo_lag\nbudget: smoke\n" + change, needle, monkeypatch,
             capsys)


def test_pbt_keeps_the_replay_buffer_in_its_checkpoints(tmp_path, monkeypatch, capsys):
    _refused(tmp_path, "task: lac/PointHazard-v0\nalgo: sac_lag\nbudget: smoke\nsearch: pbt\n"
             "pbt: {members: 2, interval: 1000}\nset: {store_replay_buffer: false}\n",
             "store_replay_buffer false with searcher pbt", monkeypatch, capsys)


# ----------------------------------------------------------------------------- end to end

def _children(db: Path, name: str | None = None):
    client = MlflowClient(f"sqlite:///{db}")
    runs = client.search_runs([e.experiment_id for e in client.search_experiments()], max_results=1000)
    parents = {r.info.run_id: r.data.tags.get("mlflow.runName") for r in runs if r.data.tags.get("lac.sweep") == "1"}
    return client, [r for r in runs if parents.get(r.data.tags.get("mlflow.parentRunId")) == (
        name or "pbt-PointHazard-v0-smoke")], parents


def _history(client, run, key):
    return [(m.step, m.value) for m in sorted(client.get_metric_history(run.info.run_id, key), key=lambda m: m.step)]


@pytest.mark.slow
def test_a_pbt_sweep_killed_mid_population_resumes_whole_and_its_winner_is_replayed_on_fresh_seeds(tmp_path):
    """From plan to confirmation, killed (SIGKILL, the driver and its workers) after its first
    exploit and resumed: no member lost or duplicated, each trained its budget once, the copy and
    its perturbed fields kept; the copy went from the best window to the worst; the winner's
    schedule replayed on fresh seeds beside the default; the population's figure on the parent run."""
    (tmp_path / "pbt.yaml").write_text(PBT_FILE.replace("interval: 1000", "interval: 500"))
    cmd = [sys.executable, str(REPO / "sweeps" / "run.py"), "--config", str(tmp_path / "pbt.yaml"),
           "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "ray_results"),
           "--max-concurrent", "2", "--confirm-top", "1", "--confirm-seeds", "2"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    copied_before = {}
    try:  # until a member has copied another (an exploit happened)
        deadline = time.time() + 400
        while time.time() < deadline and not copied_before:
            time.sleep(2)
            if (tmp_path / "ray_results" / "pbt-PointHazard-v0-smoke" / "sweep.json").exists():
                try:
                    client, members, _ = _children(tmp_path / "mlflow.db")
                except Exception:  # the store mid-write
                    continue
                copied_before = {m.data.tags["lac.trial_id"]: (json.loads(m.data.tags["lac.pbt.copies"])[0],
                                                               _history(client, m, "schedule/lr"))
                                 for m in members if "lac.pbt.copies" in m.data.tags}
        assert copied_before, "no exploit before the deadline"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        out = proc.communicate()[0]
    assert "a population of 4 members, one seed each: seeds 0..3; 8,000 env steps in all" in out
    resumed = subprocess.run([*cmd, "--resume"], cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stdout[-3000:] + resumed.stderr[-3000:]
    client, members, parents = _children(tmp_path / "mlflow.db")
    ids = [m.data.tags["lac.trial_id"] for m in members]
    assert len(members) == 4 and len(set(ids)) == 4, "no member lost, none duplicated"
    assert all(m.info.status == "FINISHED" for m in members)
    for m in members:  # each trained its budget once: the population spent 4 x 2,000 env steps
        assert [s for s, _ in _history(client, m, "env_steps")] == [500, 1000, 1500, 2000]
    for trial_id, (first, before) in copied_before.items():  # the perturbed value kept through the kill
        m, = [m for m in members if m.data.tags["lac.trial_id"] == trial_id]
        copies = json.loads(m.data.tags["lac.pbt.copies"])  # its own copies, in order; parents: its ancestry
        assert copies[0] == first and json.loads(m.data.tags["lac.pbt.parents"])[-1] == copies[-1]
        (at, donor_name), later = copies[0], [c[0] for c in copies[1:]]
        after = dict(_history(client, m, "schedule/lr"))
        perturbed = [v for s, v in before if s > at]
        if perturbed:  # logged before the kill: the same value after the resume, until its next copy
            assert all(v == perturbed[0] for s, v in after.items() if at < s <= min(later, default=math.inf))
        # The copy: from the member with the best window there to the one with the worst.
        window = {r.data.tags["mlflow.runName"]: dict(_history(client, r, OBJECTIVE_WINDOW)).get(at) for r in members}
        assert window[donor_name] == max(window.values()) and window[m.data.tags["mlflow.runName"]] == min(
            window.values())
        donor, = [r for r in members if r.data.tags["mlflow.runName"] == donor_name]
        ratio = after[at + 500] / dict(_history(client, donor, "schedule/lr"))[at]
        assert math.isclose(ratio, 0.8) or math.isclose(ratio, 1.2) or 1e-5 < after[at + 500] < 1.0
    parent = [p for p, n in parents.items() if n == "pbt-PointHazard-v0-smoke"][0]
    assert "pbt_population.png" in [a.path for a in client.list_artifacts(parent)]
    # The winner's schedule, replayed on fresh seeds beside the default.
    _, confirm, _ = _children(tmp_path / "mlflow.db", "pbt-PointHazard-v0-smoke-confirm")
    assert sorted(r.data.tags["lac.config"] for r in confirm) == ["ppo_lag-default-PointHazard-v0"] * 2 + [
        "ppo_lag-pbt1-PointHazard-v0"] * 2
    assert sorted(json.loads(r.data.params["seed"]) for r in confirm) == [2000, 2000, 3000, 3000]
    winner = max(members, key=lambda m: m.data.metrics["episode_return"] if m.data.metrics["feasible"] else -math.inf)
    with open(client.download_artifacts(winner.info.run_id, "member.json")) as f:
        schedule = json.load(f)["schedule"]
    for r in (r for r in confirm if "pbt1" in r.data.tags["lac.config"]):
        replayed = _history(client, r, "schedule/lr")
        assert [s for s, _ in replayed] == [500, 1000, 1500, 2000]
        due = [float(fields_at(schedule, s - 500)["lr"]) for s, _ in replayed]  # the iteration ending at s ran it
        assert [v for _, v in replayed] == pytest.approx(due)


@pytest.mark.slow
def test_a_groups_schedule_changes_its_fields_at_their_env_steps(ray_session, tmp_path):
    """A replayed schedule rebuilds the run with the fields due at each env step and its own state:
    its fields change there and nowhere else, and training goes on from where it was."""
    from sweeps.sweep import run_sweep

    (tmp_path / "s.yaml").write_text(
        "task: lac/PointHazard-v0\nalgo: ppo_lag\nbudget: smoke\nseeds: 1\neval_episodes: 0\ngroups:\n  replay:\n"
        "    schedule: [{at: 0, set: {lr: 0.001, clip_param: 0.2}}, {at: 1000, set: {lr: 0.003, clip_param: 0.1}}]\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(tmp_path / "s.yaml"), "--tracking-uri",
                                          f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage",
                                          str(tmp_path / "ray_results")]))
    assert not plan.trials[0].default, "a schedule is not the default"
    assert run_sweep(plan, Path(plan.storage) / plan.name, "test") == 0
    client, runs, _ = _children(tmp_path / "mlflow.db", plan.name)
    run, = runs
    assert _history(client, run, "schedule/lr") == [(500, 0.001), (1000, 0.001), (1500, 0.003), (2000, 0.003)]
    assert [v for _, v in _history(client, run, "schedule/clip_param")] == [0.2, 0.2, 0.1, 0.1]
    assert [s for s, _ in _history(client, run, "env_steps")] == [500, 1000, 1500, 2000]


# ----------------------------------------------------------------------------- sub-populations

class _Member:
    """What Tune's PBT reads and writes of a trial."""

    def __init__(self, index):
        from types import SimpleNamespace

        self.trial_id, self.experiment_tag, self.status = f"m{index}", f"m{index}", "PAUSED"
        self.config = {"__trial_index__": index, "overrides": {"lr": 1e-3}}
        self.checkpoint, self.last_result = f"own-{index}", {}
        self.temporary_state = SimpleNamespace(saving_to=None)
        self.run_metadata = SimpleNamespace(checkpoint_manager=SimpleNamespace(_latest_checkpoint_result=None))

    def is_finished(self):
        return self.status == "TERMINATED"

    def set_experiment_tag(self, tag):
        self.experiment_tag = tag

    def set_config(self, config):
        self.config = config

    @property
    def copied_from(self):
        result = self.run_metadata.checkpoint_manager._latest_checkpoint_result
        return None if result is None else result.checkpoint


class _Controller:
    def __init__(self, members):
        self.members, self.saves = members, 0

    def get_trials(self):
        return list(self.members)

    def get_live_trials(self):
        return [m for m in self.members if m.status != "TERMINATED"]

    def pause_trial(self, trial, should_checkpoint=True):
        trial.status = "PAUSED"

    def _schedule_trial_save(self, trial, result=None):
        return f"at-sync-{trial.trial_id}"

    def checkpoint(self, force=False, wait=False):
        self.saves += 1


def _report(scheduler, controller, member, t, score):
    for m in controller.members:
        if m.status == "RUNNING":
            m.status = "PAUSED"
    member.status = "RUNNING"
    return scheduler.on_trial_result(controller, member, {"env_steps": t, OBJECTIVE_WINDOW: score})


def test_sub_populations_exploit_within_themselves_at_their_intervals_and_the_slow_best_migrates():
    from sweeps.sweep import pbt_bounds, pbt_mutations
    from sweeps.sweep_file import Distribution

    search = {"lr": Distribution(loguniform=[1e-4, 1e-2])}
    scheduler = ConstrainedPBT(time_attr="env_steps", metric=OBJECTIVE_WINDOW, mode="max", intervals=(100, 200),
                               mutations=pbt_mutations(search), bounds=pbt_bounds(search), seed=0,
                               quantile_fraction=0.25)
    members = [_Member(i) for i in range(6)]  # fast: 0, 2, 4; slow: 1, 3, 5
    controller = _Controller(members)
    from ray.tune.schedulers.pbt import _PBTTrialState

    for m in members:
        scheduler._trial_state[m] = _PBTTrialState(m)
    score = {0: 5.0, 2: 1.0, 4: 3.0, 1: 50.0, 3: -1e6, 5: 10.0}  # member 1 (slow) is the best of all
    for i in (0, 2, 4, 1, 3, 5):
        _report(scheduler, controller, members[i], 100, score[i])
    # The fast sub-population exploited at 100: its worst (2) copied its best (0); the slow one did not.
    assert members[2].copied_from == "at-sync-m0" or members[2].copied_from == "own-0"
    assert all(members[i].copied_from is None for i in (0, 4, 1, 3, 5))
    assert scheduler.exploits == [1, 0] and controller.saves == 1
    assert scheduler.next_sync == [200.0, 200.0]
    for i in (0, 2, 4, 1, 3, 5):
        _report(scheduler, controller, members[i], 200, score[i])
    # At 200 both exploited: the slow one's worst (3) copied its best (1), and 1 migrated into the
    # fast one's worst, which ranks below it.
    assert members[3].copied_from in ("at-sync-m1", "own-1")
    assert scheduler.exploits == [2, 1] and scheduler.migrations == 1
    fast_copies = [members[i].copied_from for i in (0, 2, 4)]
    assert any(c in ("at-sync-m1", "own-1") for c in fast_copies)


def test_a_resumed_population_waiting_past_its_next_exploit_moves_it_on():
    scheduler = _scheduler(intervals=(100,))
    members = [_Member(i) for i in range(2)]
    controller = _Controller(members)
    from ray.tune.schedulers.pbt import _PBTTrialState

    for m in members:  # a resume: the scheduler's state is new, the members come back at 300 env steps
        scheduler._trial_state[m] = _PBTTrialState(m)
        scheduler._trial_state[m].last_train_time = 300
    assert scheduler.choose_trial_to_run(controller) in members
    assert scheduler.next_sync == [400.0]


def test_an_interval_grows_after_each_exploit():
    scheduler = ConstrainedPBT(time_attr="env_steps", metric=OBJECTIVE_WINDOW, mode="max", intervals=(100,),
                               mutations={"lr": [1e-3]}, bounds={}, seed=0, growth=2.0)
    members = [_Member(i) for i in range(2)]
    controller = _Controller(members)
    from ray.tune.schedulers.pbt import _PBTTrialState

    for m in members:
        scheduler._trial_state[m] = _PBTTrialState(m)
    for t in (100, 300):
        for i, m in enumerate(members):
            _report(scheduler, controller, m, t, float(i))
    assert scheduler.exploits == [2] and scheduler.intervals == [400.0] and scheduler.next_sync == [700.0]


def test_a_failed_member_does_not_stop_the_population():
    """A member that failed for good (Tune's ERROR: no longer live) is not waited for: the others
    exploit at their interval and go on."""
    from ray.tune.schedulers.pbt import _PBTTrialState

    scheduler = _scheduler(intervals=(100,))
    members = [_Member(i) for i in range(3)]
    controller = _Controller(members)
    for m in members:
        scheduler._trial_state[m] = _PBTTrialState(m)

    class _Live(_Controller):
        def get_live_trials(self):
            return [m for m in self.members if m.status not in ("TERMINATED", "ERROR")]

    controller = _Live(members)
    members[2].status = "ERROR"  # failed before its first exploit
    _report(scheduler, controller, members[0], 100, 5.0)
    assert scheduler.exploits == [0], "one live member still short of the interval"
    _report(scheduler, controller, members[1], 100, 1.0)
    assert scheduler.exploits == [1] and members[1].copied_from is not None and members[2].copied_from is None
    assert scheduler.choose_trial_to_run(controller) in members[:2]
