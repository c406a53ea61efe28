"""A paper's own source, brought in at run time for a golden-step recording (focops_authors.py,
respo_authors.py): one commit of the authors' repository extracted from a git mirror into a
temporary folder outside this repository, the hashes of the files a recording executes, and the
defaults its ``argparse`` declares. Nothing of the reference is copied into this repository; its
fixtures keep only what its code computed. numpy-free, lac_rllib-free."""

from __future__ import annotations

import ast
import hashlib
import io
import subprocess
import tarfile
import tempfile
from pathlib import Path


def extract(mirror: Path, commit: str, paths: list[str]) -> Path:
    """``paths`` (folders or files) of ``commit`` from the bare git repository ``mirror``, in a new
    temporary folder; returns that folder. ``commit`` must name a commit the mirror holds."""
    full = subprocess.run(["git", "--git-dir", str(mirror), "rev-parse", "--verify", f"{commit}^{{commit}}"],
                          check=True, capture_output=True, text=True).stdout.strip()
    if not full.startswith(commit):
        raise ValueError(f"{commit} resolves to {full}")
    tar = subprocess.run(["git", "--git-dir", str(mirror), "archive", "--format=tar", full, *paths],
                         check=True, capture_output=True).stdout
    out = Path(tempfile.mkdtemp(prefix="golden-ref-"))
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(out, filter="data")
    return out


def sha256(root: Path, files: list[str]) -> dict[str, str]:
    """The SHA-256 of each executed file, for the fixture's meta (which bytes produced it)."""
    return {f: hashlib.sha256((root / f).read_bytes()).hexdigest() for f in files}


def argparse_defaults(path: Path) -> dict:
    """``dest → default`` of every ``parser.add_argument(...)`` in ``path`` with a literal default:
    the hyperparameters the authors' script runs with when given no flags (read, not executed)."""
    defaults = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_argument"):
            continue
        flags = [a.value for a in node.args if isinstance(a, ast.Constant)]
        kw = {k.arg: k.value for k in node.keywords}
        if "default" not in kw or not flags:
            continue
        name = max(flags, key=len).lstrip("-").replace("-", "_")
        try:
            defaults[name] = ast.literal_eval(kw["default"])
        except ValueError:
            continue
    return defaults


def run_body(path: Path, outer: str, first: str, last: str, namespace: dict) -> dict:
    """Executes, in ``namespace``, the statements of function ``outer``'s body from the definition
    of its nested function ``first`` to that of ``last`` inclusive (the closures and whatever the
    authors set up between them: optimizers, parameters, schedulers); ``namespace`` supplies the
    locals of ``outer`` those statements read, as globals. Line numbers stay the file's own, so
    tracebacks cite the authors' lines. Returns the namespace."""
    tree = ast.parse(path.read_text(), filename=str(path))
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == outer)
    index = {n.name: i for i, n in enumerate(fn.body) if isinstance(n, ast.FunctionDef)}
    if first not in index or last not in index:
        raise LookupError(f"{path.name}: {outer}() defines no {first} or {last}")
    module = ast.Module(body=fn.body[index[first]:index[last] + 1], type_ignores=[])
    exec(compile(module, str(path), "exec"), namespace)  # noqa: S102  the authors' own code
    return namespace
