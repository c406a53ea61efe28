"""A run's env fingerprint: what decides the environment a run learns in, beside the algorithm.

The same task id is not the same environment across simulator versions (SafePO#21: Safety-Gym
against Safety-Gymnasium numbers; omnisafe#127, #311), envs per runner (safety-gymnasium#40: vector
env counts change what the algorithm sees), cost conventions or observation filters, and the
bfloat16 kernels some algorithms pick by CPU (lac_rllib/constrained/precision.py) compute
differently on a CPU without them, the backend a navigation task steps on (batched or stock:
equal step for step, yet named, so a claim rests on one), a Point task's robot, and the constraints
a run holds apart (docs/constraints.md: each its own cost, not the summed one). Every sweep
trial records its fingerprint (MLflow tag ``lac.env_fingerprint``, the whole in
``lac.env_fingerprint_json``); reports, the frontier, confirmation and the registry of tuned
configurations never rank runs whose fingerprints differ (sweeps/reports/results.py). Plain data,
no Ray.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from lac_rllib.tasks.versions import BF16_FLAGS, cpu_flags, runtime_versions

#: The simulator packages whose versions change trajectories (docs/dependencies.md).
SIMULATOR_PACKAGES = ("safety_gymnasium", "mujoco", "gymnasium")
#: The algorithm fields that change what the env hands the learner (the observation filter, the envs).
#: (The cost limit is not among them: it belongs to a configuration, and a ladder compares limits.)
OBS_FILTER = ("obs_normalization", "obs_clip", "obs_std_floor")  # the observation filter's fields
ENV_FIELDS = (*OBS_FILTER, "episode_cost_discount")
#: What an algorithm's own configuration decides rather than the task: its reference's observation
#: filter (RESPO's runs without one), its envs, its kernels. Runs of one algorithm that differ in them
#: are never ranked together; two algorithms each at their own are (a comparison compares them so).
ALGORITHM_SIDE = ("envs", *OBS_FILTER, "cpu_bf16")


def fingerprint(task: str, params: dict, num_env_runners: int = 0) -> dict[str, Any]:
    """The fingerprint of a run of ``task`` with the algorithm's ``params`` (a trial's resolved
    fields): the task's id, source and settings, the simulator's versions, the episode length, the
    envs that sample (runners × envs per runner), the cost key and discount, the observation
    filter, and whether this CPU has the bfloat16 kernels where a dtype is left to it."""
    from lac_rllib.tasks import get_task

    spec = get_task(task)
    versions = runtime_versions()
    return {
        "task": spec.id, "factory": spec.factory, "kwargs": json.loads(json.dumps(spec.kwargs, default=str)),
        "episode_steps": spec.episode_steps, "cost_source": spec.cost_source,
        "envs": max(1, num_env_runners) * int(params.get("num_envs_per_env_runner", 1)),
        **{k: params.get(k) if params.get(k) is not None else getattr(spec, k, None) for k in ENV_FIELDS},
        **{k: versions.get(k) for k in SIMULATOR_PACKAGES},
        # Only where a dtype field leaves the choice to the CPU ("auto"): elsewhere the CPU's kind
        # changes nothing the run computes, and a mixed cluster's runs stay comparable.
        "cpu_bf16": bool(cpu_flags() & set(BF16_FLAGS)) if any(
            k.endswith("_dtype") and v == "auto" for k, v in params.items()) else None,
        # Only where the task has a batched backend (a key elsewhere would change every other id).
        **({"env_backend": params.get("env_backend") or "batched"} if spec.batched else {}),
        **({"robot_variant": params.get("robot_variant") or "safety_gymnasium"} if spec.robot == "Point" else {}),
        # Only where a run holds constraints apart (``constraints``): their names, in the task's order.
        # The costs its learner sees are theirs, not the summed cost; their limits are configuration.
        **({"constraints": [c.name for c in spec.constraints if c.name in params["constraints"]]}
           if params.get("constraints") else {}),
    }


def fingerprint_id(fp: dict) -> str:
    """A short stable id of a fingerprint (equal fingerprints, equal ids)."""
    return hashlib.sha256(json.dumps(fp, sort_keys=True, default=str).encode()).hexdigest()[:12]


def environment(fp: dict) -> dict:
    """The part of a fingerprint every algorithm on the task shares (:data:`ALGORITHM_SIDE` left out)."""
    return {k: v for k, v in fp.items() if k not in ALGORITHM_SIDE}


def differences(a: dict, b: dict) -> str:
    """What differs between two fingerprints, in one line: ``mujoco 3.3.0 vs 3.2.7; envs 10 vs 1``."""
    keys = [k for k in dict.fromkeys([*a, *b]) if a.get(k) != b.get(k)]
    return "; ".join(f"{k} {a.get(k)} vs {b.get(k)}" for k in keys) or "none"
