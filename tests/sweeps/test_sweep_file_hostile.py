"""Sweep files written by a careless or hostile user (``sweeps/run.py --config FILE``): each is
refused with exit 2 in one line that names the file, the line and the key where the value came
from the file, without a traceback, before Ray starts and before any MLflow run exists; a bomb
costs neither time nor memory; names that become paths stay under --storage."""

import re
import time
import tracemalloc
from pathlib import Path

import pytest

from sweeps import run as cli
from sweeps import sweep_file

USER = "task: {factory: 'user_envs:%s', cost_limit: 5, cost_key: violation, preset: tiny}\n"
ENV = "task: {factory: 'user_envs:make_safe', cost_limit: %s, episode_cost_discount: %s, cost_key: violation}\n"


def _alias_tree(levels: int, width: int = 9) -> str:
    """``levels`` anchors, each a list of ``width`` aliases of the one before: width**levels values."""
    lines = ["a0: &a0 [1, 2, 3, 4, 5, 6, 7, 8, 9]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "x-anchors:\n" + "".join(f"  {line}\n" for line in lines) + f"set: {{actor_hidden: *a{levels - 1}}}\n"


def _nested(depth: int, opener: str = "[", closer: str = "]") -> str:
    return "grid: {nu_lr: " + opener * depth + "0.1" + closer * depth + "}\n"


# (case, file text (str) or bytes, the line named (None: the file alone), a regex the line must match)
CASES = [
    ("binary", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", 1, r"not UTF-8 text \(byte 0x89 at offset 0\)"),
    ("latin-1", "description: caf\xe9 au lait\n".encode("latin-1"), 1, r"not UTF-8 text \(byte 0xe9"),
    ("too large", "description: x\n" + "# padding\n" * 110_000, None, r"larger than 1024 KiB"),
    ("empty", "", None, r"no keys \(an empty file\)"),
    ("only a comment", "# a sweep, later\n", None, r"no keys"),
    ("a scalar", "hello\n", None, r"a sweep file is a mapping of keys .*not a str"),
    ("two documents", "budget: smoke\n---\nbudget: quick\n", 2, r"not valid YAML: but found another document"),
    ("python tag", "set: !!python/object/apply:os.system ['true']\n", 1, r"not valid YAML: could not determine a "
                                                                         r"constructor"),
    ("billion laughs", "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n" if i else "l0: &l0 [lol]\n"
                               for i in range(10)), 6, r"expands to more than 100,000 values"),
    ("alias tree in a value", _alias_tree(9), 7, r"expands to more than 100,000 values"),
    ("recursive alias", "set: &x {actor_hidden: *x}\n", 1, r"a recursive alias"),
    ("too many aliases", "x: &v 1\ngrid: {nu_lr: [" + ", ".join(["*v"] * 101) + "]}\n", 2, r"more than 100 aliases"),
    ("5,000 nested [", _nested(5_000), 1, r"nested deeper than 32 levels"),
    ("5,000 nested {", "grid: " + "{a: " * 5_000 + "1" + "}" * 5_000 + "\n", 1, r"nested deeper than 32 levels"),
    ("two grid keys", "grid: {nu_lr: [0.1]}\nbudget: smoke\ngrid: {beta: [1.0]}\n", 3,
     r"key 'grid' given twice \(lines 1 and 3\)"),
    ("seeds: 10⁹", "seeds: 1000000000\n", 1, r"seeds.count: Input should be less than or equal to 1000 "
                                             r"\(got 1000000000\)"),
    ("1,001 listed seeds", "seeds: [" + ", ".join(map(str, range(1001))) + "]\n", 1,
     r"seeds.list: Tuple should have at most 1000 items"),
    ("seed past 2³¹", "seeds: {count: 3, start: 2147483646}\n", 1, r"seeds.start: seeds 2147483646..2147483648 "
                                                                   r"pass 2147483647"),
    ("seeds.count: true", "seeds: {count: true}\n", 1, r"seeds.count: Input should be a valid integer \(got True\)"),
    ("seeds: true", "seeds: true\n", 1, r"seeds: Input should be a valid dictionary.* \(got True\)"),
    ("budget: true", "budget: true\n", 1, r"budget: budget True is invalid; accepted: smoke \| quick \| paper or env "
                                          r"steps \(an integer 1\.\.10,000,000,000\)"),
    ("budget: 0", "budget: 0\n", 1, r"budget: budget 0 is invalid; accepted: .*an integer 1\.\."),
    ("budget: -2000", "budget: -2000\n", 1, r"budget: budget -2000 is invalid"),
    ("budget: 2.5", "budget: 2.5e6\n", 1, r"budget: budget 2500000.0 is invalid"),
    ("num_samples: true", "search: {beta: {uniform: [0, 1]}}\nnum_samples: true\n", 2,
     r"num_samples: Input should be a valid integer \(got True\)"),
    ("max_concurrent: true", "max_concurrent: true\n", 1, r"max_concurrent: Input should be a valid integer"),
    ("max_concurrent: 0", "max_concurrent: 0\n", 1, r"max_concurrent: Input should be greater than or equal to 1"),
    ("cpus_per_trial: 512", "budget: smoke\ncpus_per_trial: 512\n", 2,
     r"cpus_per_trial 512 is more than this machine's \d+ CPUs; accepted: 1\.\.\d+"),
    ("cost_limit: true", ENV % ("true", 1.0), 1, r"task\[0\]\.cost_limit: Input should be a valid number "
                                                 r"\(got True\)"),
    ("cost_limit: .inf", ENV % (".inf", 1.0), 1, r"task\[0\]\.cost_limit: Input should be a finite number"),
    ("episode_cost_discount: true", ENV % (5, "true"), 1, r"task\[0\]\.episode_cost_discount: Input should be a "
                                                          r"valid number"),
    ("uniform: [true, 1]", "search: {beta: {uniform: [true, 1]}}\n", 1, r"search.beta.uniform\[0\]: Input should be a "
                                                                        r"valid number \(got True\)"),
    ("groups_at budget smok", "groups_at:\n  - budget: smok\n    groups: {g: {grid: {beta: [1.0]}}}\n", 2,
     r"groups_at\[0\]\.budget: unknown budget 'smok' is invalid; accepted: smoke \| quick \| paper"),
    ("groups_at typo", "groups_at:\n  - budget: smoke\n    gruops: {g: {}}\n", 3,
     r"groups_at\[0\]\.gruops: unknown key 'gruops' \(did you mean groups\?\)"),
    ("name: ..", "name: ..\n", 1, r"name: name '\.\.' is refused \(it becomes a path\)"),
    ("name: ../x", "name: ../x\n", 1, r"name: name '\.\./x' is refused"),
    ("name: /abs/x", "name: /abs/x\n", 1, r"name: name '/abs/x' is refused"),
    ("name: a/b", "name: a/b\n", 1, r"name: name 'a/b' is refused"),
    ("group name a/b", "groups:\n  a/b: {grid: {beta: [1.0]}}\n", 2, r"groups.a/b: name 'a/b' is refused"),
    ("user task name ../x", "task: {factory: 'user_envs:make_safe', cost_limit: 5, name: ../x}\n", 1,
     r"task\[0\]\.name: name '\.\./x' is refused"),
    ("experiment: ''", "experiment: ''\n", 1, r"experiment: experiment '' is refused"),
    ("description of 3,000", f"description: {'x' * 3000}\n", 1, r"description: String should have at most 2000 "
                                                               r"characters \(got 'x{17}\.\.\.x{18}'\)"),
    ("unknown task", "budget: smoke\ntask: SafetyPointGoal9-v0\n", 2,
     r"task\[0\]: unknown task 'SafetyPointGoal9-v0'; closest known tasks: SafetyPointGoal\d-v0, .*\(all \d+: "
     r"docs/tasks.md\)"),
    ("grid and search", "grid: {beta: [1.0]}\nsearch: {nu_lr: {loguniform: [1e-3, 1e-1]}}\n", 2,
     r"search: give search or grid/groups, not both"),
    ("unknown searcher", "search: {beta: {uniform: [0, 1]}}\nsearcher: tpee\n", 2,
     r"searcher: Input should be 'grid', 'random', 'tpe', 'motpe', 'nsga2' or 'pbt' \(got 'tpee'\)"),
    ("10⁸ trials", "grid:\n" + "".join(f"  {f}: [{', '.join(str(0.01 * (i + 1)) for i in range(100))}]\n"
                                       for f in ("nu_lr", "beta", "critic_lr", "actor_lr")), None,
     r"the sweep plans 300,000,000 trials \(tasks × configurations × algorithms × seeds\), more than --max-trials "
     r"5,000"),
    ("a huge value in a field", "set: {actor_hidden: [" + ", ".join(["-1"] * 900) + "]}\n", 1,
     r"set.actor_hidden: LAC config field actor_hidden=\(-1, -1, -1, -1, \.\.\.\) is invalid"),
    ("factory returns 42", USER % "make_int", 1, r"task\[0\]: task user_envs:make_int: the factory returned 42 "
                                                 r"\(a int\); accepted: a gymnasium.Env"),
    ("step raises", USER % "make_step_raises", 1, r"task\[0\]: task user_envs:make_step_raises: step\(action\) "
                                                  r"raised RuntimeError: physics diverged at step 1"),
    ("reset raises", USER % "make_reset_raises", 1, r"task user_envs:make_reset_raises: reset\(seed=0\) raised "
                                                    r"RuntimeError: the simulator could not load its scene"),
    ("close raises", USER % "make_close_raises", 1, r"task user_envs:make_close_raises: close\(\) raised OSError: "
                                                    r"the viewer was already gone"),
]


@pytest.fixture
def refused(tmp_path, monkeypatch, capsys):
    """Run sweeps/run.py --config on a file; return (rc, everything it printed), with Ray's start
    and MLflow's run creation made to fail the test."""
    import mlflow
    import ray

    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(Path(__file__).parent))  # user_envs
    monkeypatch.setattr(ray, "init", lambda *a, **k: pytest.fail("Ray was started for a bad file"))
    monkeypatch.setattr(mlflow.MlflowClient, "create_run", lambda *a, **k: pytest.fail("an MLflow run was created"))

    def run(config: str, *flags: str):
        rc = cli.main(["--config", config, "--storage", str(tmp_path / "rr"), *flags])
        out = capsys.readouterr()
        return rc, out.out + out.err

    return run


@pytest.mark.parametrize("case,text,line,needle", CASES, ids=[c[0] for c in CASES])
def test_a_malformed_file_is_one_line_naming_file_line_and_key(tmp_path, refused, case, text, line, needle):
    path = tmp_path / "my.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    rc, printed = refused(str(path))
    assert rc == 2, printed
    assert "Traceback" not in printed and len(printed.splitlines()) <= 3 and len(printed) < 700, printed
    where = f"{path}:{line}: " if line else f"{path}: "
    assert where in printed, f"expected {where!r} in: {printed}"
    assert re.search(needle, printed), printed
    assert not (tmp_path / "rr").exists() and not (tmp_path / "mlflow.db").exists()


@pytest.mark.parametrize("case,what,needle", [
    ("a directory", "dir", r"dir: cannot be read \(Is a directory\)"),
    ("a missing file", "missing.yaml", r"missing.yaml: cannot be read \(No such file or directory\)"),
])
def test_an_unreadable_file_is_named(tmp_path, refused, case, what, needle):
    (tmp_path / "dir").mkdir()
    rc, printed = refused(str(tmp_path / what))
    assert rc == 2 and re.search(needle, printed) and len(printed.splitlines()) == 1, printed


@pytest.mark.parametrize("flags,needle", [
    (["--seeds", "1000000000"], r"--seeds: Input should be less than or equal to 1000 \(got 1000000000\)"),
    (["--cpus-per-trial", "512"], r"--cpus-per-trial 512 is more than this machine's"),
    (["--name", "../x"], r"argument --name: name '\.\./x' is refused"),
    (["--max-trials", "2"], r"plans 3 trials .*more than --max-trials 2"),
])
def test_a_flag_s_bad_value_names_the_flag(tmp_path, refused, flags, needle):
    path = tmp_path / "ok.yaml"
    path.write_text("budget: smoke\n")
    if flags[0] == "--name":
        with pytest.raises(SystemExit):
            cli.parse_args(["--config", str(path), *flags])
        return
    rc, printed = refused(str(path), *flags)
    assert rc == 2 and re.search(needle, printed) and len(printed.splitlines()) == 1, printed


@pytest.mark.parametrize("text", [_alias_tree(10), _nested(10_000), _nested(10_000, "{a: ", "}")],
                         ids=["alias bomb (9^10)", "10,000 nested [", "10,000 nested {"])
def test_a_bomb_is_refused_within_5_s_and_200_mb(text):
    tracemalloc.start()
    t0 = time.perf_counter()
    with pytest.raises(sweep_file.SweepFileError, match=r"expands to more than|nested deeper than"):
        sweep_file.load("bomb.yaml", text)
    elapsed = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert elapsed < 5 and peak < 200 * 2**20, (elapsed, peak / 2**20)


def test_a_legal_name_s_state_stays_under_storage(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "ok.yaml"
    path.write_text("name: my-sweep.v2\nbudget: smoke\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(path), "--storage", str(tmp_path / "rr")]))
    assert Path(plan.storage) == (tmp_path / "rr").resolve() and plan.name == "my-sweep.v2"
    assert (Path(plan.storage) / plan.name).resolve().parent == Path(plan.storage)


def test_a_derived_name_is_made_safe(tmp_path, monkeypatch):
    """A file's stem becomes the default name: spaces and odd characters are replaced, not refused."""
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "my sweep (v2).yaml"
    path.write_text("budget: smoke\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(path), "--storage", str(tmp_path / "rr")]))
    assert plan.name == "my_sweep__v2_-PointHazard-v0-smoke" and sweep_file.check_name(plan.name)


def test_the_strict_schema_still_reads_what_people_write(tmp_path, monkeypatch):
    """Strictness refuses booleans and strings for numbers, not integers where a float is meant."""
    sweep = sweep_file.load("ok.yaml", "task: {factory: 'user_envs:make_safe', cost_limit: 5}\nbudget: 20000\n"
                                       "seeds: {count: 2, start: 100}\nsearch: {beta: {uniform: [0, 20]}}\n")
    assert sweep.task[0].cost_limit == 5.0 and sweep.budget == 20_000 and sweep.seed_list() == (100, 101)
    assert sweep.search["beta"].args == (0.0, 20.0)
