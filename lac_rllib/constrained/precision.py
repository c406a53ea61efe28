"""The dtype of an algorithm's matrix products: float32, or bfloat16 where the CPU multiplies it
natively. Fields whose value is "auto" resolve here, once, where the module is built, and the run
records what they resolved to (``SafeTaskConfig.resolved``: config.json, checkpoint metadata, an
MLflow tag), so a resume on a CPU that resolves otherwise is refused rather than silently changing
the numerics. Used by LAC's chain (``langevin_dtype``) and SAC-Lag's critics (``critic_dtype``).
"""

from __future__ import annotations

import torch

DTYPES = ("float32", "bfloat16")
#: What a dtype field accepts: a dtype, or "auto" (:func:`resolve_dtype`).
DTYPE_CHOICES = (*DTYPES, "auto")
TORCH_DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}
#: CPU flags (Linux /proc/cpuinfo) of native bfloat16 matmuls: AVX512-BF16 or AMX.
BF16_FLAGS = ("avx512_bf16", "amx_bf16")


def cpu_flags() -> set[str]:
    """This CPU's feature flags as Linux reports them (empty where /proc/cpuinfo is not there)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def resolve_dtype(name: str) -> str:
    """``name``, with "auto" as "bfloat16" on a CPU with native bf16 matmuls and "float32"
    elsewhere (where bf16 runs 30-50x slower: docs/speed.md)."""
    if name == "auto":
        return "bfloat16" if cpu_flags() & set(BF16_FLAGS) else "float32"
    return name
