"""An update call's minibatch loop run inside one ``TorchLearner._update`` (``update_path="fused"``).

RLlib's ``Learner.update`` cuts the train batch into minibatches with its ``MiniBatchCyclicIterator``
and calls ``_update`` once per minibatch; per call it slices and concatenates every column
(``SampleBatch`` slicing, ``concat_samples``), runs ``RLModule.forward_train`` (which sets the
whole module tree to train mode again) and logs Ray and step metrics. At the baselines' sizes
(PPO-Lag: 64-row minibatches of (64, 64) networks) that machinery costs more than the maths
(docs/speed.md). With the fused loop the algorithm asks RLlib for one ``_update`` over the whole
batch (``minibatch_size=None, num_epochs=1``) and hands the minibatch plan over in ``timesteps``
(:data:`TS_MINIBATCHES`); :class:`FusedMinibatchLoop` then steps through the same minibatches:

- the same rows in the same order: :func:`cyclic_minibatch_indices` replays the iterator's
  walk, its wrap-arounds and its reshuffles, drawing each permutation from numpy's global RNG as
  ``SampleBatch.shuffle`` does, so a seeded run makes the same draws;
- the minibatches' rows gathered with one ``index_select`` per column for 64 minibatches at a time,
  each minibatch a slice of them (:func:`gathered_minibatches`);
- the learner's own hooks, as ``TorchLearner._uncompiled_update`` calls them: ``forward_train``,
  ``compute_losses``, ``compute_gradients``, ``postprocess_gradients``, ``apply_gradients``.

The update is RLlib's bit for bit (tests/constrained/test_minibatch_loop.py replays the
iterator's rows; tests/algorithms/test_update_path.py trains both ways from one seed and compares
every weight); the steps-trained metrics count every row trained, as RLlib's per-minibatch
logging does.
"""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np
import torch
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.rl_module.rl_module import RLModule
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import (
    ALL_MODULES,
    NUM_MODULE_STEPS_TRAINED,
    NUM_MODULE_STEPS_TRAINED_LIFETIME,
)

#: The ``timesteps`` key under which an algorithm hands its minibatch plan to the learner.
TS_MINIBATCHES = "safe_minibatch_plan"
UPDATE_PATHS = ("fused", "rllib")


def minibatch_plan(*, minibatch_size: int, num_epochs: int = 1, shuffle: bool = False,
                   num_total_minibatches: int = 0) -> dict:
    """The plan :class:`FusedMinibatchLoop` follows: ``Learner.update``'s own arguments."""
    return {"minibatch_size": int(minibatch_size), "num_epochs": int(num_epochs), "shuffle": bool(shuffle),
            "num_total_minibatches": int(num_total_minibatches)}


def update_kwargs(update_path: str, **plan) -> dict:
    """The keyword arguments of ``learner_group.update`` for ``plan``: RLlib's iterator's own
    (``"rllib"``), or one ``_update`` over the whole batch with the plan in ``timesteps`` (``"fused"``;
    merge ``kwargs.pop("timesteps")`` into the call's timesteps)."""
    if update_path not in UPDATE_PATHS:
        raise ValueError(f"update_path {update_path!r}; accepted: {' | '.join(UPDATE_PATHS)}")
    if update_path == "rllib":
        return {"minibatch_size": plan["minibatch_size"], "num_epochs": plan.get("num_epochs", 1),
                "shuffle_batch_per_epoch": plan.get("shuffle", False),
                "num_total_minibatches": plan.get("num_total_minibatches", 0), "timesteps": {}}
    return {"minibatch_size": None, "num_epochs": 1, "timesteps": {TS_MINIBATCHES: minibatch_plan(**plan)}}


def cyclic_minibatch_indices(sizes: dict[Any, int], *, minibatch_size: int, num_epochs: int = 1,
                             shuffle: bool = False, num_total_minibatches: int = 0
                             ) -> Iterator[dict[Any, np.ndarray]]:
    """The row indices of each minibatch ``MiniBatchCyclicIterator`` (ray 2.60) yields for batches
    of ``sizes`` rows per module: every module walks its rows cyclically, ``minibatch_size`` rows a
    minibatch; a minibatch that reaches a batch's end takes its remaining rows, wraps around (one
    epoch covered) and, with ``shuffle``, reorders the batch by ``np.random.permutation`` (the
    global RNG, as ``SampleBatch.shuffle``). It stops once every module covered ``num_epochs``
    epochs or, if ``num_total_minibatches`` > 0, after that many minibatches."""
    order = {mid: np.arange(n) for mid, n in sizes.items()}
    start = dict.fromkeys(sizes, 0)
    covered = dict.fromkeys(sizes, 0)
    count = 0
    while ((num_total_minibatches == 0 and min(covered.values()) < num_epochs)
           or (num_total_minibatches > 0 and count < num_total_minibatches)):
        out = {}
        for mid, n in sizes.items():
            if n == 0:
                raise ValueError(f"the batch of module {mid!r} is empty")
            s, need, parts = start[mid], minibatch_size, []
            while s + need >= n:  # the iterator's test: a minibatch ending on the last row wraps too
                parts.append(order[mid][s:])
                need -= n - s
                s = 0
                covered[mid] += 1
                if shuffle:
                    order[mid] = order[mid][np.random.permutation(n)]
            if need > 0:
                parts.append(order[mid][s:s + need])
            start[mid] = s + need
            out[mid] = parts[0] if len(parts) == 1 else np.concatenate(parts)
        yield out
        count += 1


def gathered_minibatches(columns: dict[Any, dict[str, torch.Tensor]], plan: list[dict[Any, np.ndarray]],
                         chunk: int = 64) -> Iterator[dict[Any, dict[str, torch.Tensor]]]:
    """Each minibatch of ``plan`` (row indices per module) with its rows of every column: the rows
    of ``chunk`` minibatches at a time gathered in one ``index_select`` per column, each minibatch
    then a contiguous slice of them (a view: the same values, the same layout as its own gather;
    a minibatch's tensors are read, never written, by the losses)."""
    for first in range(0, len(plan), chunk):
        part = plan[first:first + chunk]
        gathered, bounds = {}, {}
        for mid, cols in columns.items():
            lengths = [len(indices[mid]) for indices in part]
            idx = torch.from_numpy(np.concatenate([indices[mid] for indices in part]))
            gathered[mid] = {k: v.index_select(0, idx) for k, v in cols.items()}
            bounds[mid] = np.concatenate([[0], np.cumsum(lengths)]).tolist()
        for j in range(len(part)):
            yield {mid: {k: v[bounds[mid][j]:bounds[mid][j + 1]] for k, v in cols.items()}
                   for mid, cols in gathered.items()}


class FusedMinibatchLoop(TorchLearner):
    """A TorchLearner mixin: an update call whose ``timesteps`` carry :data:`TS_MINIBATCHES` runs
    that plan's minibatches inside its one ``_update`` (see the module's docstring); any other
    call is RLlib's, unchanged."""

    #: Whether the current minibatch's statistics are the ones reported. RLlib's learners log a
    #: minibatch's losses with window 1, so an update reports its last minibatch's: in the fused
    #: loop only that one computes and logs them (True on RLlib's path, which cannot tell).
    reports_minibatch: bool = True
    #: The train batch's columns the learner's forward and losses read (None: every tensor column);
    #: the fused loop gathers only these for each minibatch.
    MINIBATCH_COLUMNS: tuple[str, ...] | None = None

    @override(TorchLearner)
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)
        self._minibatch_plan = (timesteps or {}).get(TS_MINIBATCHES)

    @override(TorchLearner)
    def _update(self, batch: dict[str, Any]):
        plan, self._minibatch_plan = getattr(self, "_minibatch_plan", None), None
        if plan is None:
            return super()._update(batch)
        wanted = self.MINIBATCH_COLUMNS
        columns = {mid: {k: v for k, v in b.items() if isinstance(v, torch.Tensor) and (wanted is None or k in wanted)}
                   for mid, b in batch.items()}
        sizes = {mid: len(b) for mid, b in batch.items()}
        for mid in batch:
            self.module[mid].train()  # once; TorchRLModule.forward_train sets it on every minibatch
        rows = dict.fromkeys(sizes, 0)
        fwd_out = loss_per_module = None
        plan = list(cyclic_minibatch_indices(sizes, **plan))
        try:
            for i, minibatch in enumerate(gathered_minibatches(columns, plan)):
                self.reports_minibatch = i == len(plan) - 1
                for mid in minibatch:
                    rows[mid] += len(plan[i][mid])
                if not self.reports_minibatch and self.skip_minibatch({mid: len(plan[i][mid]) for mid in minibatch}):
                    continue
                # RLModule.forward_train, not TorchRLModule's: the same forward without the train() call.
                fwd_out = {mid: RLModule.forward_train(self.module[mid], mb) for mid, mb in minibatch.items()}
                loss_per_module = self.compute_losses(fwd_out=fwd_out, batch=minibatch)
                gradients = self.compute_gradients(loss_per_module)
                self.apply_gradients(self.postprocess_gradients(gradients))
        finally:  # a failed update leaves RLlib's path reporting every minibatch, as it should
            self.reports_minibatch = True
        self._log_rows_trained(rows, sizes)
        return fwd_out, loss_per_module, {}

    def skip_minibatch(self, rows: dict[Any, int]) -> bool:
        """Whether the next minibatch (``rows`` per module) would step no network of any module and
        need no check: the learner then counts its rows as its losses would and the loop runs neither
        its forward pass nor its losses (nothing would have changed: the same update). The reported
        minibatch, the last, always runs. Never here; the on-policy learners skip what their KL early
        stop has stopped (families/on_policy/learner.py)."""
        return False

    def _log_rows_trained(self, rows: dict, sizes: dict) -> None:
        """The steps-trained metrics of the rows trained beyond the one batch RLlib counts itself,
        so the results count every minibatch's rows as RLlib's per-minibatch logging does."""
        for mid, n in rows.items():
            extra = n - sizes[mid]
            if extra <= 0:
                continue
            self.metrics.log_value((mid, NUM_MODULE_STEPS_TRAINED), extra, reduce="sum")
            self.metrics.log_value((mid, NUM_MODULE_STEPS_TRAINED_LIFETIME), extra, reduce="lifetime_sum",
                                   with_throughput=True)
            self.metrics.log_value((ALL_MODULES, NUM_MODULE_STEPS_TRAINED), extra, reduce="sum",
                                   with_throughput=True)
            self.metrics.log_value((ALL_MODULES, NUM_MODULE_STEPS_TRAINED_LIFETIME), extra,
                                   reduce="lifetime_sum", with_throughput=True)
