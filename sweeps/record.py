"""A sweep's record on disk, in its Tune directory: ``sweep.yaml`` (the resolved sweep, a file that
reruns it) and ``sweep.json`` (its parent run and plan), so ``--resume`` continues the same sweep
and refuses another one.

Kept apart from ``sweeps/sweep.py`` so the CLI can judge a start or a resume before Ray is imported.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import yaml

SWEEP_FILE = "sweep.json"
SWEEP_YAML = "sweep.yaml"
#: Settings of the resolved sweep a resume may change: they change how fast it goes, not what it runs.
SPEED_KEYS = ("max_concurrent", "cpus_per_trial", "description")
#: What a sweep is beyond its file: --resume must be given the same values.
IDENTITY_PLAN = ("tracking_uri", "timesteps", "n_trials", "optuna_storage")
IDENTITY_INFRA = ("optuna_seed",)
#: Keys a sweep recorded before they existed lacks: no difference on resume (its finished trials keep
#: the score they were ranked on, their tag ``lac.score`` absent: ``train``; the report counts them).
LATER_KEYS = ("score",)


def sweep_record(plan, parent: str) -> dict:
    """What ``sweep.json`` holds: the parent run, the plan and the settings beyond the sweep file."""
    return {"parent_run_id": parent, "plan": plan.record(),
            "infra": {k: getattr(plan.infra, k) for k in IDENTITY_INFRA}}


def write_record(sweep_dir: Path, plan, parent: str) -> None:
    sweep_dir.mkdir(parents=True, exist_ok=True)
    (sweep_dir / SWEEP_YAML).write_text(plan.sweep.dump())
    (sweep_dir / SWEEP_FILE).write_text(json.dumps(sweep_record(plan, parent), default=str))


def resume_differences(sweep_dir: Path, plan) -> list[str]:
    """``key=old (now new)`` for every defining setting that differs from the recorded sweep."""
    record = json.loads((sweep_dir / SWEEP_FILE).read_text())
    diff = []
    if (sweep_dir / SWEEP_YAML).exists():
        old = yaml.safe_load((sweep_dir / SWEEP_YAML).read_text()) or {}
        new = yaml.safe_load(plan.sweep.dump())
        for key in sorted(set(old) | set(new)):
            if key in LATER_KEYS and key not in old:
                continue
            if key not in SPEED_KEYS and old.get(key) != new.get(key):
                diff.append(f"{key}={old.get(key)!r} (now {new.get(key)!r})")
    old_plan, old_infra = record.get("plan", {}), record.get("infra", {})
    now = plan.record()
    diff += [f"{k}={old_plan[k]!r} (now {now[k]!r})" for k in IDENTITY_PLAN if k in old_plan and old_plan[k] != now[k]]
    diff += [f"--{k.replace('_', '-')}={old_infra[k]!r} (now {getattr(plan.infra, k)!r})"
             for k in IDENTITY_INFRA if k in old_infra and old_infra[k] != getattr(plan.infra, k)]
    old_envs, new_envs = old_plan.get("env_fingerprints"), now.get("env_fingerprints", {})
    if old_envs is not None and set(old_envs) != set(new_envs):  # a record from before fingerprints: no check
        from lac_rllib.tasks.fingerprint import differences

        pairs = zip(sorted(set(old_envs) - set(new_envs)), sorted(set(new_envs) - set(old_envs)))
        diff.append("the environment: " + ", ".join(differences(old_envs[a], new_envs[b]) for a, b in pairs))
    return diff


def parent_run_id(sweep_dir: Path) -> str:
    """The MLflow parent run of the sweep recorded in ``sweep_dir``."""
    return json.loads((sweep_dir / SWEEP_FILE).read_text())["parent_run_id"]


def checked_sweep_dir(plan) -> Path:
    """The sweep's Tune directory (``--storage``/NAME), checked before Ray starts: a new sweep's is
    free (or holds a start that failed early), a resumed one's records the same sweep."""
    sweep_dir = Path(plan.storage) / plan.name
    resume = plan.infra.resume
    if sweep_dir.resolve().parent != Path(plan.storage).resolve():  # a safe name cannot; a link might
        raise ValueError(f"sweep {plan.name!r}: its directory {sweep_dir} resolves outside --storage "
                         f"{plan.storage}; accepted: a name whose directory lies in --storage")
    if resume and not (sweep_dir / SWEEP_FILE).exists():
        raise ValueError(f"--resume: no sweep named {plan.name!r} under {plan.storage}")
    if resume:
        diff = resume_differences(sweep_dir, plan)
        if diff:
            raise ValueError(f"--resume: sweep {plan.name!r} was started with other settings: "
                             f"{'; '.join(diff)}. Resume with the original ones, or start a new --name")
    # A directory without a record or Tune state is a start that failed early: startable.
    started = (sweep_dir / SWEEP_FILE).exists() or any(sweep_dir.glob("experiment_state*.json"))
    if not resume and started:
        raise ValueError(f"a sweep named {plan.name!r} exists under {plan.storage}; pass --resume or --name")
    return sweep_dir


def git_commit() -> str:
    """The commit of the code that runs the sweep (its parent run's ``git_commit``)."""
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                              cwd=Path(__file__).parent).stdout.strip() or "unknown"
    except OSError:
        return "unknown"
