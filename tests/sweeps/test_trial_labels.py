"""A trial's label (sweeps/spaces.py ``TrialSpec.label``: its Tune name, its MLflow run's name and
``lac.config``) names its algorithm first and once, alike for every algorithm; a sweep recorded under
the labels before (LAC's naming no algorithm, others' theirs, a confirmation's some twice) resumes
and reads back under them."""

import json
import re
from pathlib import Path

from sweeps import followup, spaces
from sweeps import run as cli
from sweeps.record import SWEEP_FILE, write_record
from sweeps.spaces import TrialSpec
from tests.sweeps.test_followup import record_sweep

TASK = "lac/PointHazard-v0"
LADDER = f"task: {TASK}\nalgo: [lac, ppo_lag]\nbudget: smoke\nseeds: 2\ncost_limits: [0, 2]\n" \
         "frontier: {algo: ppo_lag, nu: [0, 1]}\n"
#: The ladder's trials as the code before labelled them, in the plan's order: LAC's without its algorithm.
OLD_LABELS = [f"{'' if a == 'lac' else f'{a}-'}ladder-PointHazard-v0-b{b}-s{s}"
              for a in ("lac", "ppo_lag") for b in (0, 2) for s in (0, 1)] + [
    f"ppo_lag-frontier-nu_fixed={nu}-PointHazard-v0-s{s}" for nu in (0.0, 1.0) for s in (0, 1)]


def _args(tmp_path, text, *extra):
    path = tmp_path / "ladder.yaml"
    path.write_text(text)
    return ["--config", str(path), "--experiment", "test", "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
            "--storage", str(tmp_path / "rr"), *extra]


def _plan(tmp_path, text, *extra):
    plan, = cli.make_plan(cli.parse_args(_args(tmp_path, text, *extra)))
    return plan


def test_a_label_names_its_algorithm_first_and_once_for_every_algorithm(tmp_path):
    ladder = _plan(tmp_path, LADDER)
    grid = "groups:\n  c: {grid: {algo: [lac, ppo_lag]}}\n"
    compare = _plan(tmp_path, f"task: {TASK}\nbudget: smoke\nseeds: 1\n{grid}", "--name", "compare")
    # The groups confirmations make: ALGO-tuned1, ALGO-default (a tuned comparison), baseline-ALGO (--confirm-top).
    groups = (("ppo_lag", "ppo_lag-tuned1"), ("lac", "lac-default"), ("ppo_lag", "baseline-ppo_lag"))
    confirmed = [TrialSpec(group, "", None, TASK, 2000, {"algo": algo}) for algo, group in groups]
    search = spaces.trial_spec({"task": TASK, "budget": "smoke", "sets": {"algo": "ppo_lag"}, "seeds": [0],
                                "overrides": {"clip_param": 0.25}, spaces.LABELS_KEY: spaces.LABELS})
    for t in [*ladder.trials, *compare.trials, *confirmed, search]:
        label = t.label()
        assert label.startswith(f"{t.algo}-") and re.split(r"[-=,]", label).count(t.algo) == 1, label
    assert [t.label() for t in ladder.trials[:2]] == [f"lac-ladder-PointHazard-v0-b0-s{s}" for s in (0, 1)]
    assert [t.label() for t in confirmed] == ["ppo_lag-tuned1-PointHazard-v0-s2000", "lac-default-PointHazard-v0-s2000",
                                              "ppo_lag-baseline-PointHazard-v0-s2000"]
    assert search.label() == "ppo_lag-search-clip_param=0.25-s0"
    assert {t.config_label() for t in compare.trials} == {"lac-c-PointHazard-v0", "ppo_lag-c-PointHazard-v0"}


def test_a_sweep_recorded_under_the_old_labels_resumes_and_reads_back_under_them(tmp_path):
    from sweeps.sweep import param_space

    plan = _plan(tmp_path, LADDER)
    sweep_dir = Path(plan.storage) / plan.name
    write_record(sweep_dir, plan, "parent-run")
    record = json.loads((sweep_dir / SWEEP_FILE).read_text())
    record["plan"]["trial_labels"] = OLD_LABELS  # sweep.json as the code before wrote it
    (sweep_dir / SWEEP_FILE).write_text(json.dumps(record))
    # --resume accepts it: a sweep is identified by its file and settings, not by its trials' labels.
    resumed, = cli.make_plan(cli.parse_args(_args(tmp_path, LADDER, "--resume")))
    resumed.check()
    # Tune resumes from the configs it recorded, built then without LABELS_KEY (and TrialSpecs without
    # legacy_label): the trials started after the resume are labelled as those before, one label per
    # configuration across the stop. Configs of a sweep planned now are labelled algorithm first.
    space = param_space(resumed, "parent-run")
    grid = space["trial"]["grid_search"]
    before = {k: v for k, v in space.items() if k not in ("trial", spaces.LABELS_KEY)}
    recorded = [{**before, "trial": {k: v for k, v in d.items() if k != "legacy_label"}} for d in grid]
    assert [spaces.trial_spec(c).label() for c in recorded] == OLD_LABELS
    assert [spaces.trial_spec({**space, "trial": d}).label() for d in grid] == [t.label() for t in resumed.trials]
    assert resumed.trials[0].label() == "lac-ladder-PointHazard-v0-b0-s0" != OLD_LABELS[0]
    # What those trials logged reads back under their old labels, each configuration's seeds together.
    runs = [{"group": "ladder", "seed": s, "algo": a, "old": f"{'' if a == 'lac' else f'{a}-'}ladder-PointHazard-v0-b0",
             "return": 1.0 + s, "cost": 0.0} for a in ("lac", "ppo_lag") for s in (0, 1)]
    (tmp_path / "store").mkdir()
    trials, summary = followup.read_back(record_sweep(tmp_path / "store", "recorded", runs, labels="old"))
    assert dict(zip(summary["config"], summary["n_seeds"])) == {"ladder-PointHazard-v0-b0": 2,
                                                               "ppo_lag-ladder-PointHazard-v0-b0": 2}
