"""One driver per sweep: a lock file in the sweep's Tune directory, with its owner and a heartbeat.

Two drivers on one sweep (easy after Ctrl-C on ``ray job submit``, which leaves the job running)
would train the same trials into the same MLflow runs. The first driver creates ``driver.lock``
atomically (O_EXCL) and rewrites its heartbeat every ``HEARTBEAT_S``; another driver finds the
file and refuses, naming the owner's host and pid, unless the owner is gone: its process no longer
exists on this host, or (another host) its heartbeat is older than ``STALE_S``. Then it takes the
lock over (a driver killed with SIGKILL cannot clean up).
Works wherever the storage path is a filesystem every driver sees (local, NFS); object stores
(``s3://``) have no atomic create, and there the lock is skipped with a warning (:func:`sweep_lock`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

LOCK_FILE = "driver.lock"
HEARTBEAT_S = 15.0
STALE_S = 90.0


def _dead_here(held: dict) -> bool:
    """The owner ran on this host and its process no longer exists (killed, e.g. SIGKILL)."""
    if held.get("host") != socket.gethostname():
        return False
    try:
        os.kill(int(held.get("pid", 0)), 0)
    except ProcessLookupError:
        return True
    except (OSError, ValueError):
        return False
    return False


class SweepLocked(RuntimeError):
    """Another live driver holds the sweep."""


class DriverLock:
    def __init__(self, sweep_dir: Path | str):
        self.path = Path(sweep_dir) / LOCK_FILE
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.owner = {"host": socket.gethostname(), "pid": os.getpid()}

    def _write(self, fd: int | None = None) -> None:
        data = json.dumps({**self.owner, "heartbeat": time.time()}).encode()
        if fd is not None:
            os.write(fd, data)
            return
        tmp = self.path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, self.path)  # readers never see a half-written file

    def acquire(self) -> None:
        """Take the lock or raise :class:`SweepLocked` naming its live owner."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    held = json.loads(self.path.read_text())
                except (OSError, ValueError):
                    held = {"heartbeat": 0.0}  # unreadable: treat as stale
                age = time.time() - float(held.get("heartbeat", 0.0))
                if age < STALE_S and not _dead_here(held):
                    raise SweepLocked(
                        f"sweep is being run by another driver: host {held.get('host')} pid {held.get('pid')} "
                        f"(heartbeat {age:.0f} s ago); stop it first, or wait {STALE_S:.0f} s after it died") from None
                print(f"taking over the lock of a driver that is gone (host {held.get('host')} pid "
                      f"{held.get('pid')}, last heartbeat {age:.0f} s ago)", file=sys.stderr)
                self.path.unlink(missing_ok=True)
                continue
            try:
                self._write(fd)
            finally:
                os.close(fd)
            self._thread = threading.Thread(target=self._beat, name="sweep-lock-heartbeat", daemon=True)
            self._thread.start()
            return
        raise SweepLocked(f"could not take {self.path}: another driver took it at the same time")

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            try:
                self._write()
            except OSError:
                pass  # a storage hiccup: the next beat retries; STALE_S is several beats

    def release(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        try:
            held = json.loads(self.path.read_text())
            if (held.get("host"), held.get("pid")) == (self.owner["host"], self.owner["pid"]):
                self.path.unlink()
        except (OSError, ValueError):
            pass

    def __enter__(self) -> "DriverLock":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


@contextlib.contextmanager
def sweep_lock(sweep_dir: Path | str, storage: str) -> Iterator[None]:
    """The driver lock of the sweep in ``sweep_dir``, held for the block (raises :class:`SweepLocked`
    on entry where a live driver holds it); none where ``storage`` is an object store, with a warning."""
    if "://" in storage:  # no atomic create there
        print(f"note: no driver lock on {storage}: do not run this sweep from two drivers at once", file=sys.stderr)
        yield
        return
    with DriverLock(sweep_dir):
        yield
