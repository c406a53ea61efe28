"""The package's face: its version, its public names, its console scripts, and a Langevin chain
(and Lagrange multiplier) that import no RLlib."""

import importlib.metadata
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import lac_rllib

ROOT = Path(__file__).resolve().parents[1]


def test_version_is_the_installed_one():
    assert lac_rllib.__version__ == importlib.metadata.version("lac-rllib")


@pytest.mark.parametrize("name", [n for n in lac_rllib.__all__ if n != "__version__"])
def test_public_names_resolve(name):
    assert getattr(lac_rllib, name).__name__ == name


def test_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        _ = lac_rllib.Nope


@pytest.mark.parametrize("module", ["lac_rllib.algorithms.lac.langevin", "lac_rllib.constrained.lagrange",
                                    "lac_rllib.constrained.networks", "lac_rllib.tasks"])
def test_plain_modules_import_no_rllib(module):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m == 'ray' or m.startswith('ray.')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"{module} pulls in {out.strip()[:200]}"


@pytest.mark.parametrize("script", ["lac-train", "lac-sweep", "lac-eval"])
def test_console_scripts_answer_help(script):
    exe = shutil.which(script, path=str(Path(sys.executable).parent))
    assert exe, f"{script} is not installed beside {sys.executable}"
    out = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith(f"usage: {script} "), out.stdout[:200] + out.stderr[-500:]


def test_no_sys_path_edits_in_package_code():
    offenders = [str(p.relative_to(ROOT)) for d in ("lac_rllib", "sweeps") for p in (ROOT / d).rglob("*.py")
                 if "sys.path.insert" in p.read_text(encoding="utf-8")]
    assert offenders == []


def _imports(path: Path) -> set[str]:
    """The modules of lac_rllib and sweeps that ``path`` imports (top level or inside functions)."""
    import ast

    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return {n for n in names if n.startswith(("lac_rllib", "sweeps"))}


def test_imports_go_one_way():
    """sweeps -> algorithms -> families -> constrained -> tasks; inside an algorithm only RLlib's
    Config <-> Algorithm pattern points back (the config names its algorithm, module and learner classes)."""
    package = ROOT / "lac_rllib"
    bad = []
    for path in sorted(package.rglob("*.py")):
        mine, rel = _imports(path), str(path.relative_to(ROOT))
        if rel.startswith(("lac_rllib/constrained/", "lac_rllib/tasks/", "lac_rllib/algorithms/",
                           "lac_rllib/families/")):
            bad += [f"{rel} imports {m}" for m in mine if m.startswith("sweeps")]
        if rel.startswith(("lac_rllib/constrained/", "lac_rllib/tasks/", "lac_rllib/families/")):
            bad += [f"{rel} imports {m}" for m in mine if m.startswith("lac_rllib.algorithms")]
        if rel.startswith(("lac_rllib/constrained/", "lac_rllib/tasks/")):
            bad += [f"{rel} imports {m}" for m in mine if m.startswith("lac_rllib.families")]
        if rel.startswith("lac_rllib/tasks/"):
            bad += [f"{rel} imports {m}" for m in mine if m.startswith("lac_rllib.constrained")]
        if rel.startswith("lac_rllib/algorithms/lac/") and not rel.endswith(("config.py", "algorithm.py")):
            bad += [f"{rel} imports {m}" for m in mine if m.startswith("lac_rllib.algorithms.lac.config")]
    assert bad == []


ALGO_DIR = ROOT / "lac_rllib" / "algorithms"


def test_no_algorithm_folder_imports_another_but_its_house():
    """What two algorithms share lives in lac_rllib/families/ (the on-policy, trust-region and
    off-policy bases) and lac_rllib/constrained/ (the multiplier, plumbing); an algorithm built on
    another (its config class extends the other's: FOCOPS, CUP, RESPO on PPO-Lag, PCPO on CPO;
    registry.house) imports that folder and no other: a folder importing another's learner that is
    not its declared base fails."""
    from lac_rllib.algorithms.registry import ALGOS, house

    folders = sorted(p.name for p in ALGO_DIR.iterdir() if (p / "__init__.py").exists())
    assert set(ALGOS) <= set(folders)
    houses = {name: house(name) for name in folders if name in ALGOS}
    assert {houses[a] for a in ("focops", "cup", "respo")} == {"ppo_lag"} and houses["pcpo"] == "cpo"
    assert all(houses[a] is None for a in ("lac", "ppo_lag", "sac_lag", "p3o", "trpo_lag", "cpo"))
    crossing = [f"{path.relative_to(ROOT)} imports {m}"
                for name in folders for path in sorted((ALGO_DIR / name).rglob("*.py"))
                for m in _imports(path)
                if m.startswith("lac_rllib.algorithms.")
                and m.split(".")[2] not in (name, "registry", houses.get(name))]
    assert not crossing, crossing


#: The one module outside the algorithm folders that names algorithms in code, by design: the
#: plain-torch copy of each baseline's step, which update_step.py times beside the learners'.
STILL_NAMING = {"benchmarks/reference_steps.py"}


def test_no_module_outside_the_algorithm_folders_names_an_algorithm():
    """An algorithm's knowledge (its budgets' sizes, plan rates, reported keys, family overrides)
    is declared in its folder and read through the registry: no string literal elsewhere names one."""
    import ast

    from lac_rllib.algorithms.registry import ALGOS

    naming = []
    for path in sorted([*ROOT.glob("lac_rllib/**/*.py"), *ROOT.glob("sweeps/**/*.py"), *ROOT.glob("benchmarks/*.py")]):
        rel = str(path.relative_to(ROOT))
        if rel.startswith("lac_rllib/algorithms/") or rel in STILL_NAMING:
            continue
        tree = ast.parse(path.read_text())
        docs = {id(n.body[0].value) for n in ast.walk(tree)
                if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef)) and n.body
                and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
        naming += [f"{rel}:{n.lineno}: {n.value!r}" for n in ast.walk(tree)
                   if isinstance(n, ast.Constant) and n.value in ALGOS and id(n) not in docs]
    assert not naming, naming


def test_reporting_and_running_do_not_import_each_other():
    """The reports (sweeps/reports/) read what trials report (sweeps/objective.py) and how
    configurations are written (sweeps/reports/configurations.py), never the runner's modules; no
    module borrows another's private names."""
    import ast

    bad = []
    for path in sorted((ROOT / "sweeps").rglob("*.py")):
        reading = path.parent.name == "reports"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sweeps")):
                continue
            bad += [f"{path.name} imports {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
            if reading and node.module in ("sweeps.sweep", "sweeps.trainable", "sweeps.run"):
                bad.append(f"{path.name} imports {node.module}")
    assert not bad, bad


#: The repository's Python, by folder: its modules and how they import one another.
LAYERS = ("lac_rllib", "sweeps", "benchmarks")


def module_graph() -> dict[str, set[str]]:
    """Module → the repository's modules it imports (top level or inside functions). A benchmark
    imports a sibling by its bare name (its folder is on sys.path), so a bare name that is a
    module of the importer's own folder counts as that module."""
    import ast

    modules = {".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
               for d in LAYERS for p in (ROOT / d).rglob("*.py") if "__pycache__" not in p.parts}
    graph = {}
    for m, p in modules.items():
        folder = m.rsplit(".", 1)[0] if p.name != "__init__.py" else m
        names = set()
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                # from PACKAGE import SUBMODULE is the submodule; from MODULE import NAME the module
                names.update(f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                             for a in node.names)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        deps = set()
        for n in names:
            if m.startswith("benchmarks") and f"{folder}.{n}" in modules:
                n = f"{folder}.{n}"
            while n and n not in modules:  # a name inside a module: the module
                n = n.rpartition(".")[0]
            if n and n != m:
                deps.add(n)
        graph[m] = deps
    return graph


def import_circle(graph: dict[str, set[str]]) -> list[str] | None:
    """The first import circle of ``graph`` (depth first, in name order), or None."""
    done, path = set(), []

    def visit(m):  # a module met again on the current path closes a circle
        if m in path:
            return path[path.index(m):] + [m]
        if m in done:
            return None
        path.append(m)
        for n in sorted(graph[m]):
            if circle := visit(n):
                return circle
        path.pop()
        done.add(m)
        return None

    return next((c for m in sorted(graph) if (c := visit(m))), None)


def test_no_import_circle_in_the_repository():
    """No circle among the modules of lac_rllib/, sweeps/ and benchmarks/, imports inside functions
    included; the sweep CLI (sweeps/run.py) imports the rest of sweeps/ and none of them imports it."""
    graph = module_graph()
    assert {"lac_rllib.families.on_policy.learner", "sweeps.run", "benchmarks.revision"} <= set(graph)
    assert "benchmarks.revision" in graph["benchmarks.update_step"]  # bare sibling imports are followed
    circle = import_circle(graph)
    assert circle is None, "import circle: " + " -> ".join(circle)
    assert not [m for m, deps in graph.items() if "sweeps.run" in deps and m.startswith("sweeps")]


def test_the_circle_check_finds_a_circle():
    """It can fail: a circle put into a copy of the graph is found and named."""
    graph = module_graph()
    plan = sorted(graph["sweeps.run"])[0]  # run imports it: an import back closes a circle
    graph[plan] = graph[plan] | {"sweeps.run"}
    circle = import_circle(graph)
    assert circle is not None and circle[0] == circle[-1] and {"sweeps.run", plan} <= set(circle)
