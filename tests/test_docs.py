"""The documents the code cites are in the repository and say what the code does (fast, no Ray).

- docs/config.md is generated from ``LACParams`` and ``PRESETS``, so it cannot drift;
- every ``docs/spec.md §N`` citation names a section that exists, and every
  ``docs/spec.md, "Name"`` / ``docs/dependencies.md, "Name"`` citation a heading that exists;
- nothing points outside the repository any more (the specification and the dependency notes
  used to live in a sibling folder);
- docs/architecture.md names only paths that exist, and every module of lac_rllib/ and sweeps/;
- no file under docs/ nor README.md holds a machine's absolute paths (run roots are RUN_DIR/...).
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from pathlib import Path

import pytest

from lac_rllib.algorithms.lac.config import LACParams
from lac_rllib.config_doc import REGENERATE, config_markdown

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
CODE_DIRS = ("lac_rllib", "sweeps", "benchmarks", "tests")
# Files outside CODE_DIRS that cite the docs (docs/fidelity/ is evidence and is left as it was).
OTHER_FILES = ("README.md", "install.sh", "pyproject.toml", "docker/Dockerfile", "docker/README.md",
               "docs/speed.md", "docs/speed/iteration.md", "docs/config.md")

# "SPEC §1", "docs/spec.md §5", "docs/spec.md §1-5": one section or a range.
SECTION_CITE = re.compile(r"(?:\bSPEC|docs/spec\.md),? §(\d+)(?:\s*[-–]\s*(\d+))?")
# 'docs/dependencies.md, "Safety-Gymnasium"': a heading of that document.
NAMED_CITE = re.compile(r'docs/(spec|dependencies)\.md,?\s+"([^"]+)"')
# Pointers to the old out-of-repo files, and bare "SPEC" citations (word-bounded, so names such
# as SPECS or _SAFETY_SPECS are fine).
OUTSIDE = ("NOTES.md", "SPEC.md", "../shared")
BARE_SPEC = re.compile(r"\bSPEC\b")


def code_files() -> list[Path]:
    files = [p for d in CODE_DIRS for p in sorted((ROOT / d).rglob("*.py")) if "__pycache__" not in p.parts]
    return [p for p in files if p != Path(__file__).resolve()]


def cited_files() -> list[Path]:
    return code_files() + [ROOT / f for f in OTHER_FILES if (ROOT / f).exists()]


def rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def headings(doc: str) -> set[str]:
    text = (DOCS / f"{doc}.md").read_text(encoding="utf-8")
    return {m.group(1).strip() for m in re.finditer(r"^#+ (.+)$", text, re.MULTILINE)}


def spec_sections() -> set[int]:
    return {int(m.group(1)) for h in headings("spec") if (m := re.match(r"(\d+)\. ", h))}


def test_config_md_is_generated_from_the_code():
    path = DOCS / "config.md"
    assert path.exists(), f"docs/config.md is missing; generate it with: {REGENERATE}"
    text, expected = path.read_text(encoding="utf-8"), config_markdown()
    if text != expected:
        diff = "\n".join(list(difflib.unified_diff(text.splitlines(), expected.splitlines(), "docs/config.md",
                                                   "config_markdown()", lineterm=""))[:30])
        pytest.fail(f"docs/config.md is out of date with lac_rllib/algorithms/lac/config.py; regenerate it with: "
                    f"{REGENERATE}\n{diff}")


@pytest.mark.parametrize("field", dataclasses.fields(LACParams), ids=lambda f: f.name)
def test_every_field_is_documented_with_its_default(field):
    text = (DOCS / "config.md").read_text(encoding="utf-8")
    row = f"| `{field.name}` | `{repr(field.default).replace('|', chr(92) + '|')}` |"
    assert row in text, f"docs/config.md has no row {row!r}; regenerate it with: {REGENERATE}"


def test_spec_has_the_numbered_sections():
    assert spec_sections() == set(range(1, 8)), sorted(spec_sections())
    assert {"Notation", "Rule for defaults", "Sources"} <= headings("spec")


def test_section_citations_point_at_existing_sections():
    sections, bad, count = spec_sections(), [], 0
    for path in cited_files():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for m in SECTION_CITE.finditer(line):
                count += 1
                first, last = int(m.group(1)), int(m.group(2) or m.group(1))
                if first > last or not set(range(first, last + 1)) <= sections:
                    bad.append(f"{rel(path)}:{n}: {m.group(0)}")
    assert count > 0, "no docs/spec.md §N citation found: is the pattern still right?"
    assert not bad, "citations of sections docs/spec.md does not have:\n" + "\n".join(bad)


def test_named_citations_point_at_existing_headings():
    known = {doc: headings(doc) for doc in ("spec", "dependencies")}
    bad = []
    for path in cited_files():
        text = path.read_text(encoding="utf-8")
        for m in NAMED_CITE.finditer(text):  # the whole text: a citation may wrap after the comma
            if m.group(2) not in known[m.group(1)]:
                bad.append(f"{rel(path)}:{text.count(chr(10), 0, m.start()) + 1}: {' '.join(m.group(0).split())}")
    assert not bad, "citations of headings the document does not have:\n" + "\n".join(bad)


def test_nothing_points_outside_the_repository():
    bad = []
    for path in cited_files():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if any(s in line for s in OUTSIDE) or BARE_SPEC.search(line):
                bad.append(f"{rel(path)}:{n}: {line.strip()}")
    assert not bad, ("cite docs/spec.md §N or docs/dependencies.md (the specification and the dependency "
                     "notes live in docs/):\n" + "\n".join(bad))


# A path of this repository named in the docs or the code, e.g. `lac_rllib/algorithms/lac/learner.py`.
REPO_PATH = re.compile(r"\b((?:lac_rllib|sweeps|tests|benchmarks|docs)/[\w./-]*\w)")
URL = re.compile(r"https?://[^\s)\]>\"']+")


def test_every_repository_path_named_exists():
    """Paths in the docs and docstrings follow the code when it moves (docs/fidelity/ is evidence of
    its day and keeps the paths of then)."""
    docs = [p for p in DOCS.rglob("*.md") if "fidelity" not in p.parts]
    bad = []
    for path in sorted(set(cited_files() + docs + [ROOT / "README.md"])):
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            urls = [u.span() for u in URL.finditer(line)]  # another repository's paths (a link's)
            for m in REPO_PATH.finditer(line):
                if any(a <= m.start() < b for a, b in urls):
                    continue
                target = m.group(1).split("::")[0].rstrip(".")
                if not (ROOT / target).exists() and "*" not in target and "<" not in target:
                    bad.append(f"{rel(path)}:{n}: {target}")
    assert not bad, "paths that do not exist:\n" + "\n".join(bad)


# docs/architecture.md's folder tree: a line is its indentation (two spaces a level), one name or a
# few ("plan.py, record.py, lock.py"; a folder ends in "/") and what they hold.
ARCHITECTURE = DOCS / "architecture.md"
TREE_LINE = re.compile(r"^( *)((?:[\w.-]+/?, )*[\w.-]+/?)(?:\s+\S.*)?$")
PACKAGES = ("lac_rllib", "sweeps", "benchmarks")
# What the page names in backticks: `lac_rllib/constrained/cpus.py`, `tasks/`, `lac_rllib.constrained`.
BACKTICKED = re.compile(r"`([^`\s]+)`")
TOP_FOLDERS = ("lac_rllib/", "sweeps/", "tests/", "benchmarks/", "docs/", "docker/")
MODULE_NAME = re.compile(r"^(?:lac_rllib|sweeps)(?:\.\w+)*(?:\.\*)?$")


def architecture_tree() -> list[str]:
    """Every path the folder tree of docs/architecture.md names (folders without their "/")."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    block = text.split("## The folders", 1)[1].split("```", 2)[1]
    folders: list[str] = []  # the folders above the current line
    paths = []
    for n, line in enumerate(block.splitlines(), 1):
        if not line.strip():
            continue
        m = TREE_LINE.match(line)
        assert m, f"docs/architecture.md, folder tree line {n} is not 'NAME[, NAME...]  what': {line!r}"
        depth = len(m.group(1)) // 2
        assert depth <= len(folders), f"docs/architecture.md, folder tree line {n} is under no folder: {line!r}"
        del folders[depth:]
        names = m.group(2).split(", ")
        paths += ["/".join([*folders, name.rstrip("/")]) for name in names]
        if len(names) == 1 and names[0].endswith("/"):
            folders.append(names[0].rstrip("/"))
    return paths


def test_architecture_names_only_paths_that_exist():
    """Every path of the folder tree, every repository path and module named in backticks, and every
    file named bare (`langevin.py`, `tasks/`) is in the repository."""
    tree = architecture_tree()
    bad = [f"folder tree: {p}" for p in tree if not (ROOT / p).exists()]
    text = ARCHITECTURE.read_text(encoding="utf-8")
    for m in BACKTICKED.finditer(text):
        name, line = m.group(1), text.count("\n", 0, m.start()) + 1
        if name.startswith(TOP_FOLDERS):
            exists = (ROOT / name.split("::")[0]).exists()
        elif MODULE_NAME.match(name):
            path = ROOT / name.removesuffix(".*").replace(".", "/")
            exists = path.is_dir() or path.with_suffix(".py").exists()
        elif name.endswith((".py", "/")):
            exists = any(p == name.rstrip("/") or p.endswith("/" + name.rstrip("/")) for p in tree)
        else:
            continue
        if not exists:
            bad.append(f"line {line}: `{name}`")
    for n, line in enumerate(text.splitlines(), 1):
        bad += [f"line {n}: {m.group(1)}" for m in REPO_PATH.finditer(line)
                if not (ROOT / m.group(1).split("::")[0].rstrip(".")).exists() and "<" not in m.group(1)]
    assert not bad, "docs/architecture.md names paths that do not exist:\n" + "\n".join(bad)


def test_architecture_names_every_module():
    """Every module of lac_rllib/, sweeps/ and benchmarks/ is a line of the folder tree (an
    __init__.py may be named by its folder), so a new module comes with its line; the other way,
    test_architecture_names_only_paths_that_exist."""
    tree = set(architecture_tree())
    modules = sorted(rel(p) for d in PACKAGES for p in (ROOT / d).rglob("*.py") if "__pycache__" not in p.parts)
    missing = [m for m in modules if m not in tree and not (m.endswith("/__init__.py") and m.rsplit("/", 1)[0] in tree)]
    assert not missing, ("docs/architecture.md's folder tree does not name these modules (add a line each, "
                         "under its folder):\n" + "\n".join(missing))


# A machine's absolute path, e.g. /work/fidelity-runs/pointgoal1-campaign/runs/defaults/seed0 or
# sqlite:////root/sweep/mlflow.db: not after a word character, "." or "-", so a repository path
# (docs/fidelity/...) or a URL's path (github.com/home/...) does not count.
ABSOLUTE_RUN_PATH = re.compile(r"(?<![\w.-])/(?:work|root|home|tmp|Users|mnt|scratch|data)/[\w.-]+")


def text_files(folder: Path) -> list[Path]:
    """The text files under ``folder`` (images and other binaries left out)."""
    return [p for p in sorted(folder.rglob("*")) if p.is_file() and b"\0" not in p.read_bytes()]


def test_no_machine_paths_in_the_docs():
    """Run directories and stores are written with the run root as a placeholder (RUN_DIR/...), so the
    docs hold no machine's paths: every file under docs/ and README.md."""
    bad = []
    for path in [*text_files(DOCS), ROOT / "README.md"]:
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            bad += [f"{rel(path)}:{n}: {m.group(0)}" for m in ABSOLUTE_RUN_PATH.finditer(line)]
    assert not bad, ("absolute paths of a machine in the docs (write the run root as RUN_DIR, e.g. "
                     "RUN_DIR/pointgoal1-campaign/runs/defaults/seed0):\n" + "\n".join(bad))
