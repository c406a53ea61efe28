"""A sweep's record on disk (``sweep.json`` in its Tune directory): its parent run, its plan and the
arguments that define it, so ``--resume`` continues the same sweep and refuses another one.

Kept apart from ``sweeps/sweep.py`` so the CLI can judge a resume before Ray is imported.
"""

from __future__ import annotations

#: What a sweep is: --resume must be given the same values (the trials keep the settings they
#: started with, so a changed one would silently mix two sweeps).
IDENTITY_ARGS = ("space", "task", "budget", "seeds", "num_samples", "scheduler", "optuna_seed", "set", "experiment")
IDENTITY_PLAN = ("tracking_uri", "timesteps", "n_trials", "optuna_storage")
SWEEP_FILE = "sweep.json"


def sweep_record(plan, args, parent: str) -> dict:
    """What ``sweep.json`` holds: the parent run, the plan and the arguments that define the sweep."""
    return {"parent_run_id": parent, "plan": plan.record(),
            "args": {k: getattr(args, k) for k in IDENTITY_ARGS}}


def resume_differences(record: dict, plan, args) -> list[str]:
    """``name=old (now new)`` for every defining setting that differs from the recorded sweep."""
    old_args, old_plan = record.get("args", {}), record.get("plan", {})
    diff = [f"--{k.replace('_', '-')}={old_args[k]!r} (now {getattr(args, k)!r})"
            for k in IDENTITY_ARGS if k in old_args and old_args[k] != getattr(args, k)]
    diff += [f"{k}={old_plan[k]!r} (now {getattr(plan, k)!r})"
             for k in IDENTITY_PLAN if k in old_plan and old_plan[k] != getattr(plan, k)]
    return diff
