"""Checkpoint integrity: the SHA-256 of every file of a checkpoint, recorded on the MLflow run that
logs it and checked before a checkpoint downloaded from MLflow is restored.

RLlib checkpoints are pickles: restoring one runs whatever code its bytes name. A checkpoint is
therefore code and must come from a trusted source. The manifest does not make an untrusted
checkpoint safe; it makes sure the bytes restored are the bytes the trial wrote, so that write
access to the artifact store alone (a shared directory, an S3 bucket) cannot swap them.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

#: Run tag holding the manifest: compact JSON {relative path: sha256 hex}.
CHECKSUM_TAG = "lac.checkpoint_sha256"


class IntegrityError(ValueError):
    """A checkpoint's files are not the ones recorded."""


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def manifest(checkpoint_dir: str | Path) -> dict[str, str]:
    """{path relative to the checkpoint: sha256} for every file under ``checkpoint_dir``."""
    root = Path(checkpoint_dir)
    return {p.relative_to(root).as_posix(): _sha256(p) for p in sorted(root.rglob("*")) if p.is_file()}


def manifest_tag(checkpoint_dir: str | Path) -> str:
    return json.dumps(manifest(checkpoint_dir), sort_keys=True, separators=(",", ":"))


def verify(checkpoint_dir: str | Path, recorded: str | None) -> None:
    """Raise :class:`IntegrityError` (one line, naming the file) unless the files match ``recorded``."""
    if not recorded:
        raise IntegrityError(f"no SHA-256 manifest recorded for {checkpoint_dir} (tag {CHECKSUM_TAG}); "
                             "refusing to unpickle an unverified checkpoint")
    expected, actual = json.loads(recorded), manifest(checkpoint_dir)
    for name in sorted(expected.keys() | actual.keys()):
        if name not in actual:
            raise IntegrityError(f"checkpoint file {name} is missing")
        if name not in expected:
            raise IntegrityError(f"checkpoint file {name} was not in the checkpoint when it was logged")
        if expected[name] != actual[name]:
            raise IntegrityError(f"checkpoint file {name} does not match its recorded SHA-256 (modified after logging)")
