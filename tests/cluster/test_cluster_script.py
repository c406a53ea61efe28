"""docker/cluster.sh keeps its state private and reads it as data (fast: starts nothing)."""

import os
import stat
import subprocess
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "docker" / "cluster.sh"


def _sh(root: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "LAC_CLUSTER_DIR": str(root)}
    return subprocess.run(["bash", str(SCRIPT), *args], env=env, capture_output=True, text=True, timeout=60)


def test_state_dir_is_created_private(tmp_path):
    root = tmp_path / "state"
    assert _sh(root, "stop").returncode == 0
    assert stat.S_IMODE(root.stat().st_mode) == 0o700


def test_cluster_env_is_read_as_data_not_run(tmp_path):
    root = tmp_path / "state"
    root.mkdir(mode=0o700)
    marker = tmp_path / "ran"
    (root / "cluster.env").write_text(f"MLFLOW_PORT=$(touch {marker})\ntouch {marker}\nWORKERS=3\n")
    proc = _sh(root, "env")
    assert proc.returncode == 0, proc.stderr
    assert not marker.exists(), "cluster.env was executed"
    assert f"$(touch {marker})" in proc.stdout  # the value, verbatim


def test_a_state_dir_owned_by_another_user_is_refused(tmp_path):
    if os.geteuid() == 0:  # root can give a directory away
        root = tmp_path / "state"
        root.mkdir(mode=0o755)
        (root / "cluster.env").write_text("WORKERS=1\n")
        os.chown(root, 65534, 65534)  # nobody
    else:  # anyone else finds one that is not theirs
        root = Path("/usr")
    proc = _sh(root, "env")
    assert proc.returncode != 0 and "belongs to another user" in proc.stderr
