"""Sweep files: the built-in spaces as files expand to the trials they always ran, and every bad
file is refused before Ray starts with one line naming the file, the key and what is accepted."""

import itertools
import re
import sys
import textwrap
from pathlib import Path

import pytest

from lac_rllib.algorithms.registry import algos_text
from lac_rllib.errors import ANNOUNCE
from sweeps import run as cli
from sweeps import spaces, sweep_file

# ---------------------------------------------------------------- the spaces as they were written in
# sweeps/spaces.py before sweep files (commit c9ca59a): the reference the files must reproduce.
LEGACY_PAPER_TASKS = ("SafetyPointGoal1-v0", "SafetyCarGoal1-v0", "SafetyPointButton1-v0", "SafetyCarButton1-v0",
                      "focops/AntVelocity-v0", "focops/SwimmerVelocity-v0", "focops/HumanoidVelocity-v0",
                      "focops/HumanoidCircle-v0")
LEGACY_ABLATION = {"NI": ("langevin_steps", (30, 50, 100, 200, 500), {"langevin_start": "noninformative"}),
                   "VT": ("langevin_steps", (10, 20, 30, 40, 50, 100), {}),
                   "PR": ("beta", (0.0, 1.0, 5.0, 10.0, 20.0), {})}
LEGACY_QUICK_ABLATION = {"NI": ("langevin_steps", (20, 30), {"langevin_start": "noninformative"}),
                         "VT": ("langevin_steps", (10, 20, 30), {}), "PR": ("beta", (0.5, 1.0), {})}
LEGACY_SMOKE = {"smoke": ("langevin_steps", (5, 10), {})}
LEGACY_SEARCH = {"langevin_steps": ("int", 10, 100), "langevin_step_size": ("log", 1e-5, 1e-3),
                 "temperature": ("log", 1e-4, 1e-2), "beta": ("uniform", 0.0, 20.0)}


#: Issue 23 added one arm to the ablation: LAC unconstrained (ν pinned at 0).
UNCONSTRAINED = {"nu_lr": 0.0, "nu_init": 0.0}


def legacy_grid(space, task, seeds, budget):
    from lac_rllib.tasks import get_task

    task = task or {"smoke": "lac/PointHazard-v0", "paper": None}.get(space, "lac/PointHazard-v0")
    if space == "compare":
        from lac_rllib.algorithms.registry import ALGOS

        algos = tuple(ALGOS)  # every algorithm of the package since issue 33 (3 before: lac, ppo_lag, sac_lag)
        return [("compare", "algo", a, task, s, {"algo": a}) for a in algos for s in range(seeds)]
    if space == "paper":
        return [("paper", "", None, t, s, {}) for t in ((task,) if task else LEGACY_PAPER_TASKS) for s in range(seeds)]
    tiny = budget == "quick" and get_task(task).preset == "tiny"
    groups = (LEGACY_QUICK_ABLATION if tiny else LEGACY_ABLATION) if space == "ablation" else LEGACY_SMOKE
    trials = [(g, p, v, task, s, {**fixed, p: v}) for g, (p, values, fixed) in groups.items() for v in values
              for s in range(seeds)]
    reference = [("unconstrained", "", None, task, s, UNCONSTRAINED) for s in range(seeds)]
    return trials + (reference if space == "ablation" else [])


def _plan(tmp_path, monkeypatch, *argv):
    monkeypatch.chdir(tmp_path)
    plan, = cli.make_plan(cli.parse_args(["--storage", str(tmp_path / "rr"), *argv]))
    return plan


@pytest.mark.parametrize("space,task,seeds,budget", [
    *itertools.product(("ablation", "smoke", "compare", "paper"), (None, "SafetyPointGoal1-v0"), (1, 3),
                       ("quick", "paper")),
    ("ablation", "lac/PointHazard-v0", 2, "smoke"),
])
def test_each_builtin_space_expands_to_the_trials_it_always_ran(tmp_path, monkeypatch, space, task, seeds, budget):
    argv = ["--space", space, "--seeds", str(seeds), "--budget", budget, *(["--task", task] if task else [])]
    plan = _plan(tmp_path, monkeypatch, *argv)
    got = [(t.group, t.param, t.value, t.task, t.seed, t.overrides) for t in plan.trials]
    assert got == legacy_grid(space, task, seeds, budget)


def test_the_search_file_is_the_search_space_it_always_was(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "search")
    kind = {"int": "int", "loguniform": "log", "uniform": "uniform"}
    assert {k: (kind[d.kind], *d.args) for k, d in plan.sweep.search.items()} == LEGACY_SEARCH
    assert (plan.sweep.searcher, plan.n_trials, plan.seeds, plan.task) == ("tpe", 60, (0, 1, 2), "lac/PointHazard-v0")


def _write(tmp_path, text):
    path = tmp_path / "my.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def test_a_user_file_sweeps_any_field_of_several_algorithms_from_chosen_seeds(tmp_path, monkeypatch):
    path = _write(tmp_path, """
        task: SafetyPointGoal1-v0
        budget: 50000
        seeds: {count: 2, start: 100}
        set: {obs_clip: 10}
        grid:
          nu_lr: [0.01, 0.05]
          critic_lr: [1e-4, 3e-4]
        """)
    plan = _plan(tmp_path, monkeypatch, "--config", str(path))
    assert plan.n_trials == 8 and plan.timesteps == 50_000 and plan.seeds == (100, 101)
    assert {t.seed for t in plan.trials} == {100, 101}
    t = plan.trials[0]
    assert (t.group, t.param, t.params["nu_lr"], t.params["critic_lr"], t.params["obs_clip"]) == \
        ("my", "nu_lr,critic_lr", 0.01, 1e-4, 10)
    assert len({tr.config_label() for tr in plan.trials}) == 4
    # Flags win over the file.
    plan = _plan(tmp_path, monkeypatch, "--config", str(path), "--seeds", "3", "--seed-start", "7",
                 "--set", "obs_clip=3.0", "--name", "other")
    assert plan.seeds == (7, 8, 9) and plan.trials[0].params["obs_clip"] == 3.0 and plan.name == "other"


def test_seed_start_trains_the_seeds_asked_for(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "smoke", "--seed-start", "100", "--seeds", "3")
    assert sorted({t.seed for t in plan.trials}) == [100, 101, 102]
    assert plan.sweep.seed_list() == (100, 101, 102)


def test_the_resolved_sweep_is_a_file_that_reruns_it(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--space", "ablation", "--seeds", "2", "--set", "nu_max_adaptive=False")
    again = _write(tmp_path, plan.sweep.dump())
    replay = _plan(tmp_path, monkeypatch, "--config", str(again))
    assert [t.label() for t in replay.trials] == [t.label() for t in plan.trials]
    assert [t.params for t in replay.trials] == [t.params for t in plan.trials]


BAD = [
    ("grdi: {nu_lr: [0.1]}\n", r"my.yaml:1: grdi: unknown key 'grdi' \(did you mean grid\?\); accepted: description"),
    ("grid: {nu_lrr: [0.1]}\n", r"my.yaml:1: grid.nu_lrr: unknown lac field 'nu_lrr' \(did you mean nu_lr\?\)"),
    ("grid:\n  nu_lr: [0.1, -1.0]\n", r"my.yaml:2: grid.nu_lr\[1\]: LAC config field nu_lr=-1.0 is invalid; accepted"),
    ("search:\n  temperature: {loguniform: [0.0, 1.0]}\n",
     r"my.yaml:2: search.temperature: loguniform: low 0.0 must be > 0"),
    ("search:\n  langevin_steps: {int: [0, 10]}\n",
     r"search.langevin_steps.int: LAC config field langevin_steps=0 is invalid; accepted: an integer >= 1"),
    ("search:\n  beta: {uniform: [0, 1], int: [0, 1]}\n", r"search.beta: give exactly one of choice"),
    ("algo: ppo_lag\ngrid: {langevin_steps: [5]}\n", r"grid.langevin_steps: a field of lac, not of ppo_lag"),
    ("groups:\n  c: {grid: {algo: [lac, ppo_lag]}, set: {beta: 1.0}}\n",
     r"groups.c.set.beta: a field of lac, not of ppo_lag"),
    ("grid: {nu_lr: []}\n", r"my.yaml:1: grid.nu_lr: an empty list of values"),
    ("grid: {}\n", r"an empty grid"),
    ("task: Nope-v0\n", r"unknown task 'Nope-v0'"),
    ("budget: huge\n", r"budget: unknown budget 'huge' is invalid; accepted: smoke \| quick \| paper or env steps"),
    ("seeds: [1, 1]\n", r"seeds.list: \[1, 1\] must hold distinct seeds"),
    ("grid: {nu_lr: [0.1]\n", r"my.yaml:2: not valid YAML"),
    ("task: {factory: 'x'}\n", r"task\[0\]"),
    ("- a\n- b\n", r"a sweep file is a mapping of keys"),
    ("search: {actor_hidden: {choice: [[64, 64]]}}\n",
     r"my.yaml:1: search.actor_hidden.choice: \[\[64, 64\]\]: choice values are numbers, strings, booleans or null"),
]


@pytest.mark.parametrize("text,needle", BAD)
def test_a_bad_file_is_one_line_naming_the_key_before_ray(tmp_path, monkeypatch, capsys, text, needle):
    import ray

    path = _write(tmp_path, text)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(ray, "init", lambda *a, **k: pytest.fail("Ray was started for a bad file"))
    rc = cli.main(["--config", str(path), "--storage", str(tmp_path / "rr")])
    err = "".join(line for line in capsys.readouterr().err.splitlines(keepends=True)
                  if not line.startswith(ANNOUNCE))  # a user's module is announced before its import
    assert rc == 2 and re.search(needle, err), err
    assert err.count("\n") == 1 and "Traceback" not in err and not (tmp_path / "rr").exists()


def test_the_reference_in_docs_is_generated_from_the_schema():
    doc = (Path(__file__).resolve().parents[2] / "docs" / "sweeps.md").read_text()
    body = doc.partition(sweep_file.REFERENCE_BEGIN)[2].partition(sweep_file.REFERENCE_END)[0]
    assert body.strip() == sweep_file.reference_markdown().strip(), "run: python -m sweeps.sweep_file"


def test_yaml_reads_numbers_as_people_write_them():
    sweep = sweep_file.load("x.yaml", "grid: {temperature: [1e-4, 1E-3, 2.5e+0]}\n")
    assert sweep.grid["temperature"] == (1e-4, 1e-3, 2.5)


def test_a_search_samples_with_the_searcher_the_file_names(tmp_path, monkeypatch):
    path = _write(tmp_path, """
        searcher: random
        num_samples: 4
        seeds: [5, 9]
        search:
          nu_lr: {loguniform: [1e-3, 1e-1]}
          langevin_steps: {choice: [5, 10]}
          beta: {quniform: [0.0, 2.0, 0.5]}
        """)
    plan = _plan(tmp_path, monkeypatch, "--config", str(path))
    assert plan.n_trials == 8 and plan.sweep.searcher == "random" and plan.seeds == (5, 9)
    space = spaces.tune_search_space(plan.sweep.search)
    assert space["langevin_steps"].categories == [5, 10] and space["beta"].sampler.q == 0.5
    spec = spaces.trial_spec({"task": plan.task, "budget": plan.budget, "sets": plan.sets, "seeds": [5, 9],
                              "overrides": {"nu_lr": 0.01, "langevin_steps": 5, "beta": 1.0}, "__trial_index__": 1,
                              spaces.LABELS_KEY: spaces.LABELS})
    assert spec.seed == 9 and spec.params["nu_lr"] == 0.01 and spec.label() == "lac-search-nu_lr=0.01-T=5-beta=1-s9"


# ---------------------------------------------------------------- a user's own env (tests/sweeps/user_envs.py)
USER_ENV = "task: {factory: 'user_envs:%s', cost_limit: 5, cost_key: violation, preset: tiny}\n"


@pytest.mark.parametrize("factory,needle", [
    ("make_costless", r"my.yaml:1: task\[0\]: task user_envs:make_costless: its step info has no 'violation' "
                      r"\(keys: none\); accepted: an env that reports the step's cost"),
    ("make_dict_obs",
     r"task\[0\]: task user_envs:make_dict_obs: its observation space is Dict\(.*accepted: a flat Box"),
    ("no_such_function", r"task\[0\]: task user_envs:no_such_function: cannot be built \(AttributeError"),
])
def test_a_user_env_the_algorithms_cannot_train_on_is_refused_before_ray(tmp_path, monkeypatch, capsys, factory,
                                                                          needle):
    test_a_bad_file_is_one_line_naming_the_key_before_ray(tmp_path, monkeypatch, capsys, USER_ENV % factory, needle)


def test_a_user_env_is_a_task_of_the_plan_with_its_definition(tmp_path, monkeypatch):
    plan = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, USER_ENV % "make_safe" + "seeds: 2\n")))
    (task,) = plan.tasks
    spec = plan.user_tasks[task]
    assert task == "user/user_envs.make_safe" and (spec["obs_dim"], spec["act_dim"], spec["cost_limit"]) == (2, 1, 5.0)
    assert spec["kwargs"]["module_path"] == str(Path(__file__).parent)  # where trials import it from
    assert [t.params["cost_limit"] for t in plan.trials] == [None, None]  # the task's limit: 5
    from lac_rllib.tasks import get_task

    env = get_task(task).make({})
    env.reset(seed=0)
    assert set(env.step(env.action_space.sample())[4]) >= {"cost", "violation"}


def test_a_user_module_beside_the_sweep_file_is_found(tmp_path, monkeypatch):
    (tmp_path / "beside_envs.py").write_text((Path(__file__).parent / "user_envs.py").read_text())
    text = "task: {factory: 'beside_envs:make_safe', cost_limit: 5, cost_key: violation}\n"
    plan = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, text)))
    assert plan.user_tasks[plan.task]["kwargs"]["module_path"] == str(tmp_path)


# ---------------------------------------------------------------- a user's own algorithm (tests/algorithms/toy_algo.py)
TOY = "tests.algorithms.toy_algo"
REPO = Path(__file__).resolve().parents[2]


def test_a_users_algorithm_named_by_module_is_planned_with_its_own_fields_and_sizes(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(REPO))
    text = f"algo: {{module: {TOY}}}\nbudget: smoke\nseeds: 2\nset: {{toy_marker: 2.5}}\n"
    plan = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, text)))
    assert [t.algo for t in plan.trials] == [TOY, TOY] and plan.sweep.algo == (TOY,)
    params = plan.trials[0].params
    assert (params["toy_marker"], params["hidden"], params["train_batch_size_per_learner"]) == (2.5, (16, 16), 400)
    assert plan.user_algos == {TOY: str(REPO)}  # the folder its trials import it from
    assert plan.trials[0].config_label() == f"{TOY}-my-PointHazard-v0"
    # The resolved sweep names it by its path, and reruns the same trials.
    replay = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, plan.sweep.dump())))
    assert [t.params for t in replay.trials] == [t.params for t in plan.trials]
    # Beside a built-in one, in a grid, by the same path.
    both = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, f"grid: {{algo: [ppo_lag, {TOY}]}}\n"
                                                                         "budget: smoke\nseeds: 1\n")))
    assert [t.algo for t in both.trials] == ["ppo_lag", TOY] and "toy_marker" not in both.trials[0].params


def test_a_users_algorithm_beside_the_sweep_file_is_found(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "path", list(sys.path))
    (tmp_path / "beside_algo.py").write_text((REPO / "tests" / "algorithms" / "toy_algo.py").read_text())
    plan = _plan(tmp_path, monkeypatch, "--config", str(_write(tmp_path, "algo: {module: beside_algo}\nseeds: 1\n"
                                                                         "budget: smoke\n")))
    assert plan.trials[0].algo == "beside_algo" and plan.user_algos == {"beside_algo": str(tmp_path)}


BAD_ALGO = [
    ("algo: {module: nowhere.algo}\n", r"my.yaml:1: algo\[0\]: unknown algo 'nowhere.algo'; accepted: "
     + re.escape(algos_text()) + r", or the import path of your own algorithm's module"),
    ("algo:\n  - lac\n  - {module: half_algo}\n",
     r"my.yaml:3: algo\[1\]: algo half_algo: its module must define one config class named 'half_algo'"),
    ("algo: {modul: half_algo}\n", r"my.yaml:1: algo: \{'modul': 'half_algo'\}: accepted: an algorithm's name, or "
                                   r"your own algorithm's module as \{module: IMPORT.PATH\}"),
    ("grid:\n  algo: [lac, broken_algo]\n", r"my.yaml:2: grid.algo\[1\]: algo broken_algo: cannot be imported "
                                            r"\(RuntimeError: needs a GPU\)"),
    ("search:\n  algo: {choice: [lac, nowhere.algo]}\n", r"my.yaml:2: search.algo\[1\]: unknown algo 'nowhere.algo'"),
]


@pytest.mark.parametrize("text,needle", BAD_ALGO)
def test_a_users_algorithm_that_cannot_run_is_one_line_before_ray(tmp_path, monkeypatch, capsys, text, needle):
    monkeypatch.setattr(sys, "path", list(sys.path))
    (tmp_path / "half_algo.py").write_text("CONFIG_CLASS = object\nACTIONS = ('generator',)\n")  # no config class
    (tmp_path / "broken_algo.py").write_text("raise RuntimeError('needs a GPU')\n")
    test_a_bad_file_is_one_line_naming_the_key_before_ray(tmp_path, monkeypatch, capsys, text, needle)


def test_set_algo_names_a_users_module_or_says_which_flag_was_wrong(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"^--set algo: unknown algo 'nowhere.algo'; accepted: lac"):
        _plan(tmp_path, monkeypatch, "--space", "paper", "--set", "algo=nowhere.algo")
    monkeypatch.syspath_prepend(str(REPO))
    plan = _plan(tmp_path, monkeypatch, "--space", "paper", "--task", "lac/PointHazard-v0", "--seeds", "1",
                 "--set", f"algo={TOY}")
    assert plan.trials[0].algo == TOY and plan.sweep.algo == (TOY,) and plan.user_algos == {TOY: str(REPO)}
