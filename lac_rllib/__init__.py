"""lac-rllib: LAC (Langevin Actor-Critic) and safe-RL baselines on RLlib's new API stack, with a
Tune + Optuna + MLflow sweep service (``sweeps``). docs/architecture.md says which folder holds what.

The public names below load on first use (PEP 562), so ``import lac_rllib.tasks`` or the plain-torch
Langevin chain does not pay for importing RLlib.
"""

from __future__ import annotations

import importlib

from lac_rllib import moved_modules

__version__ = "0.3.0"
moved_modules.install()  # checkpoints written before a module moved still restore

#: Public name -> the module that defines it.
_EXPORTS = {
    "LAC": "lac_rllib.algorithms.lac.algorithm",
    "LACConfig": "lac_rllib.algorithms.lac.config",
    "LACParams": "lac_rllib.algorithms.lac.config",
    "LACTorchLearner": "lac_rllib.algorithms.lac.learner",
    "LACTorchRLModule": "lac_rllib.algorithms.lac.module",
    "ChainSettings": "lac_rllib.algorithms.lac.langevin",
    "langevin_chain": "lac_rllib.algorithms.lac.langevin",
    "LagrangeMultiplier": "lac_rllib.constrained.lagrange",
    "TaskSpec": "lac_rllib.tasks",
    "get_task": "lac_rllib.tasks",
    "known_tasks": "lac_rllib.tasks",
    "evaluate": "lac_rllib.evaluation",
    "restore_policy": "lac_rllib.evaluation",
}
__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'lac_rllib' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
