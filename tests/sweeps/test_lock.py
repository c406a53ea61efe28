"""sweeps/lock.py: one driver per sweep (owner + heartbeat), and the CLI refusing a second one."""

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sweeps import run as cli
from sweeps.lock import LOCK_FILE, STALE_S, DriverLock, SweepLocked, sweep_lock
from sweeps.record import write_record

REPO = Path(__file__).resolve().parents[2]


def test_second_driver_is_refused_and_a_dead_ones_lock_is_taken_over(tmp_path):
    first = DriverLock(tmp_path)
    first.acquire()
    try:
        with pytest.raises(SweepLocked, match=f"host {socket.gethostname()} pid {os.getpid()}"):
            DriverLock(tmp_path).acquire()
    finally:
        first.release()
    assert not (tmp_path / LOCK_FILE).exists()
    # A driver killed with SIGKILL leaves its file. On another host: free once its heartbeat is stale.
    (tmp_path / LOCK_FILE).write_text(json.dumps({"host": "elsewhere", "pid": 1, "heartbeat": time.time() - 5}))
    with pytest.raises(SweepLocked, match="host elsewhere pid 1"):
        DriverLock(tmp_path).acquire()
    stale = time.time() - STALE_S - 1
    (tmp_path / LOCK_FILE).write_text(json.dumps({"host": "elsewhere", "pid": 1, "heartbeat": stale}))
    with DriverLock(tmp_path) as lock:
        assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == os.getpid() == lock.owner["pid"]
    # On this host: free at once when its process is gone.
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / LOCK_FILE).write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid,
                                                  "heartbeat": time.time()}))
    with DriverLock(tmp_path):
        pass


def test_two_resume_drivers_at_once(tmp_path):
    base = ["--space", "smoke", "--budget", "smoke", "--seeds", "2", "--experiment", "test",
            "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", "--storage", str(tmp_path / "ray_results")]
    plan, = cli.make_plan(cli.parse_args(base))
    sweep_dir = Path(plan.storage) / plan.name
    write_record(sweep_dir, plan, "parent-run")
    with DriverLock(sweep_dir):  # the first driver, alive
        proc = subprocess.run([sys.executable, str(REPO / "sweeps" / "run.py"), *base, "--resume"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert f"another driver: host {socket.gethostname()} pid {os.getpid()}" in proc.stderr
    assert "Started a local Ray instance" not in proc.stdout + proc.stderr


def test_sweep_lock_holds_the_block_and_skips_an_object_store_with_a_note(tmp_path, capsys):
    with sweep_lock(tmp_path, str(tmp_path)):
        assert (tmp_path / LOCK_FILE).exists()
        with pytest.raises(SweepLocked, match=f"pid {os.getpid()}"), sweep_lock(tmp_path, str(tmp_path)):
            pass
    assert not (tmp_path / LOCK_FILE).exists()
    with sweep_lock(tmp_path / "s3:" / "bucket", "s3://bucket"):
        pass
    assert "note: no driver lock on s3://bucket" in capsys.readouterr().err
    assert not (tmp_path / "s3:").exists()
