"""The observation filter of docs/spec.md §5: RLlib's running mean/std filter with the std floored.

[C] normalises with (s − mean) / max(std, 1e-2), clipped to ±5. RLlib's ``MeanStdFilter``
divides by std + 1e-8, so an observation dimension that barely varies (a lidar bin that is
almost always 0, a contact flag) is blown up to ±clip by noise of 1e-6. The floor keeps such a
dimension near 0. Only the division differs: the running statistics, their merge across env
runners and the checkpointed state are RLlib's own.
"""

from __future__ import annotations

import numpy as np
from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter
from ray.rllib.utils.annotations import override
from ray.rllib.utils.filter import MeanStdFilter as _RunningMeanStd


class _FlooredRunningMeanStd(_RunningMeanStd):
    """RLlib's running mean/std filter for one Box observation, dividing by max(std, floor)."""

    def __init__(self, shape, *, std_floor: float, **kwargs):
        super().__init__(shape, **kwargs)
        if self.no_preprocessor:
            raise ValueError("FlooredMeanStdFilter supports Box observations only (no dict/tuple spaces)")
        self.std_floor = float(std_floor)

    @override(_RunningMeanStd)
    def __call__(self, x, update: bool = True):
        x = np.asarray(x)
        orig_dtype = x.dtype
        rs = self.running_stats
        if update:
            rs.push(x)
            self.buffer.push(x)
        if self.demean:
            x = x - rs.mean
        if self.destd:
            std = rs.std
            x = x / (np.maximum(std, self.std_floor) if self.std_floor > 0 else std + 1e-8)
        if self.clip:
            x = np.clip(x, -self.clip, self.clip)
        return x.astype(orig_dtype)


class FlooredMeanStdFilter(MeanStdFilter):
    """``MeanStdFilter`` (env-to-module connector) whose per-agent filters floor the std."""

    def __init__(self, *args, std_floor: float = 1e-2, **kwargs):
        self.std_floor = float(std_floor)
        super().__init__(*args, **kwargs)

    @override(MeanStdFilter)
    def get_ctor_args_and_kwargs(self):
        # RLlib records the kwargs of MeanStdFilter.__init__ only; a checkpoint must rebuild
        # this class with its floor.
        args, kwargs = super().get_ctor_args_and_kwargs()
        return args, {**kwargs, "std_floor": self.std_floor}

    @override(MeanStdFilter)
    def _init_new_filters(self):
        super()._init_new_filters()
        # Same shapes and settings as RLlib's; set_state/merge_states mutate these in place.
        self._filters = {
            agent_id: _FlooredRunningMeanStd(f.shape, std_floor=self.std_floor, demean=f.demean,
                                             destd=f.destd, clip=f.clip)
            for agent_id, f in self._filters.items()
        }
