"""Where a sweep runs and records, and its checks before Ray starts: the Ray cluster, the Tune
storage, the MLflow store (on a cluster, one every node shares), a search's Optuna study.

The command line's, not the sweep file's: they differ per machine (sweeps/run.py reads them from
its flags and the environment).
"""

from __future__ import annotations

import dataclasses
import os
import socket
from pathlib import Path


@dataclasses.dataclass(frozen=True)
class Infra:
    """Where a sweep runs and records (the command line's, not the sweep file's: they differ per machine)."""

    address: str | None  #: the Ray cluster; None: a local Ray
    address_from: str | None  #: "--address" or "RAY_ADDRESS" (what ``ray job submit`` sets)
    tracking_uri: str
    storage: str  #: as given (``Plan.storage`` is resolved)
    resume: bool
    max_failures: int
    optuna_seed: int
    optuna_storage: str | None = None  #: as given (None: beside the MLflow store)
    registry: str | None = None  #: the tuned configurations (``--registry``; None: the repository's tuned/)


def check_address(address: str | None, source: str | None = "--address") -> None:
    """The Ray head at ``address`` accepts a connection (None, auto, local: nothing to check).
    ``source`` says where the address came from: ``--address``, or ``RAY_ADDRESS`` (what
    ``ray job submit`` sets for the driver it starts)."""
    if address in (None, "auto", "local"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"{source} {address!r}: accepted: auto, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as e:
        raise ValueError(f"{source} {address}: cannot connect ({e}); is `ray start --head` running there?") from None


def check_storage(storage: str) -> None:
    # The sweep's record, lock and Tune state are written through the local filesystem: a URI
    # such as s3://bucket/x used to become a local directory named "s3:" (pathlib folds "//").
    if "://" in storage and not storage.startswith("file://"):
        raise ValueError(f"--storage {storage}: object stores are not supported yet; accepted: a filesystem path "
                         "(on a cluster, one every node mounts at the same place, e.g. NFS)")
    path = Path(storage.removeprefix("file://")).resolve()
    missing = [p for p in (path, *path.parents) if not p.exists()]
    try:  # create it to know it can be (root passes os.access checks on /proc), then leave no trace
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".lac-write-probe-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as e:
        raise ValueError(f"--storage {storage} is not a writable directory ({e.strerror}); "
                         "accepted: a directory this user can create and write") from None
    finally:
        for p in missing:  # deepest first
            try:
                p.rmdir()
            except OSError:
                pass


def check_shared(uri: str, storage: str, source: str | None = "--address") -> None:
    """On a cluster every trial runs on some node: the tracking store and the storage path must
    be the same place for all of them, not one local copy per node."""
    if uri.startswith(("sqlite:", "file:")) or "://" not in uri:
        raise ValueError(f"--tracking-uri {uri} with {source}: each node would write its own local store; "
                         "accepted: http(s)://HOST:PORT of an mlflow server every node reaches (docker/README.md)")
    if not storage.startswith("file://") and not os.path.isabs(storage):
        raise ValueError(f"--storage {storage} with {source}: a relative path is a different directory on every "
                         "node; accepted: an absolute path every node mounts at the same place")


def default_optuna_storage(tracking_uri: str, storage: str) -> str:
    """``optuna.db`` beside a local MLflow store (sqlite), else in the Tune storage directory.

    Only the driver writes it (Tune's searcher runs there), so a file is enough on a cluster too.
    """
    if tracking_uri.startswith("sqlite:///"):
        folder = Path(tracking_uri[len("sqlite:///"):]).parent
    else:
        folder = Path(storage.removeprefix("file://")).resolve()
    return f"sqlite:///{folder / 'optuna.db'}"


def check_optuna_study(url: str, name: str, resume: bool) -> None:
    """A fresh search must not adopt a study left by another sweep of the same name."""
    if not url.startswith(("sqlite:///", "postgresql", "mysql")):
        raise ValueError(f"--optuna-storage {url!r}: accepted: an SQLAlchemy URL (sqlite:///PATH.db, postgresql://…, "
                         "mysql://…)")
    if resume or (url.startswith("sqlite:///") and not Path(url[len("sqlite:///"):]).exists()):
        return
    import optuna

    try:
        studies = {s.study_name for s in optuna.get_all_study_summaries(url)}
    except Exception as e:  # any failure means the storage is unusable
        raise ValueError(f"--optuna-storage {url}: cannot be opened ({e})") from None
    if name in studies:
        raise ValueError(f"an Optuna study named {name!r} exists in {url}; pass --resume, another --name, or "
                         f"delete it (optuna delete-study --storage {url} --study-name {name})")
