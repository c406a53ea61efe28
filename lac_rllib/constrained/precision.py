"""The dtype of an algorithm's matrix products: float32, or bfloat16 where the CPU multiplies it
natively. Fields whose value is "auto" resolve here, once, where the module is built, and the run
records what they resolved to (``SafeTaskConfig.resolved``: config.json, checkpoint metadata, an
MLflow tag), so a resume on a CPU that resolves otherwise is refused rather than silently changing
the numerics. Used by LAC's chain (``langevin_dtype``) and SAC-Lag's critics (``critic_dtype``).
"""

from __future__ import annotations

import torch

from lac_rllib.tasks.versions import BF16_FLAGS, cpu_flags

DTYPES = ("float32", "bfloat16")
#: What a dtype field accepts: a dtype, or "auto" (:func:`resolve_dtype`).
DTYPE_CHOICES = (*DTYPES, "auto")
TORCH_DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}


def resolve_dtype(name: str) -> str:
    """``name``, with "auto" as "bfloat16" on a CPU with native bf16 matmuls and "float32"
    elsewhere (where bf16 runs 30-50x slower: docs/speed.md)."""
    if name == "auto":
        return "bfloat16" if cpu_flags() & set(BF16_FLAGS) else "float32"
    return name
