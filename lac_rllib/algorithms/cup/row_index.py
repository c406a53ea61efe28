"""AddRowIndex: the learner connector that numbers a train batch's rows, so a shuffled minibatch
finds its rows in a whole-batch tensor (CUP's snapshot of π_stage1, learner.py)."""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns
from ray.rllib.utils.annotations import override

#: Each row's position in the batch the learner connector completed (0 … N−1, phantom rows included).
ROW_INDEX = "row_index"


class AddRowIndex(ConnectorV2):
    """Writes ``ROW_INDEX``; placed last in the pipeline, the order it numbers is that of the
    batch the cost GAE keeps (``CostGAE.last_batch``). RLlib's minibatch iterator and the fused
    loop slice and shuffle it with every other column."""

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        for columns in batch.values():
            mask = columns.get(Columns.LOSS_MASK)
            if mask is not None:
                columns[ROW_INDEX] = torch.arange(len(mask), device=getattr(mask, "device", None))
        return batch
