"""The reach critic's inputs: V_p at collection and the reachability targets (a learner connector).

RESPO's target for V_p(s_t) is the discounted indicator of a violation from t on, computed
backwards within each path [G RESPOBuffer.finish_path]:

    p_t = max( 1[c_t > 0], γ_p·p_{t+1} ).

The tail p_T after the path's last step: 0 at a terminal [G]; at a cut (a time-out, or the chunk
RLlib's sampling ended) V_p(s_T) here, read at the chunk's phantom row (the row
``AddOneTsToEpisodesAndTruncate`` appends, masked by ``LOSS_MASK``), as the other critics
bootstrap there. [G] appends float(V_C(s_T) > 0) instead, which is 1 wherever the cost critic is
positive: every cut path's last states then look unsafe (docs/baselines.md, "RESPO on PPO-Lag's house").

V_p(s) at collection, i.e. before this update changes it [G: ``pval`` in finish_path], rides in
the batch: the loss weighs its surrogates by it, and ν's step by its mean (learner.py). With K
constraints each has its own V_pk and targets from its own cost column.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns
from ray.rllib.utils.annotations import override
from ray.rllib.utils.numpy import convert_to_numpy

from lac_rllib.constrained.costs import COSTS

# The train batch's reachability columns, row-aligned with ``costs``.
REACH_PROBS = "reach_probs"  # V_p(s) at collection
REACH_TARGETS = "reach_targets"  # p_t, the reach critic's regression target


def reach_targets(costs, reach_probs, terminateds, mask, *, gamma: float) -> np.ndarray:
    """p_t of rows in episode-chunk order, each chunk's real rows followed by its phantom row (numpy,
    one entry per row): p_t = max(1[c_t > 0], γ_p·(1 − terminated_t)·p_{t+1}), where p of a phantom
    row is ``reach_probs`` there, V_p(s_T). Phantom rows' outputs are 0."""
    mask = np.asarray(mask, dtype=bool)
    out = np.zeros(len(mask), dtype=np.float32)
    tail = 0.0
    for t in reversed(range(len(mask))):
        if not mask[t]:  # the state a chunk stopped at: V_p(s_T) bootstraps its last step
            tail = float(reach_probs[t])
            continue
        tail = max(float(costs[t] > 0), gamma * (1.0 - float(terminateds[t])) * tail)
        out[t] = tail
    return out


class ReachTargets(ConnectorV2):
    """Writes ``REACH_PROBS`` (V_p at collection) and ``REACH_TARGETS`` (p_t), after ``CostGAE``.

    ``safe_fraction`` (module id → mean of 1 − V_p(s) over the last batch's real rows) is what ν's
    step weighs the violation by (learner.py)."""

    def __init__(self, input_observation_space=None, input_action_space=None, *, gamma: float):
        super().__init__(input_observation_space, input_action_space)
        self.gamma = float(gamma)
        self.safe_fraction: dict[str, float] = {}

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        for module_id, columns in batch.items():
            module = rl_module[module_id].unwrapped()
            if not hasattr(module, "compute_reach_probs") or COSTS not in columns:
                continue
            with torch.no_grad():
                probs_t = module.compute_reach_probs(columns)
            probs = convert_to_numpy(probs_t)
            mask = convert_to_numpy(columns[Columns.LOSS_MASK]).astype(bool)
            costs, terminateds = convert_to_numpy(columns[COSTS]), convert_to_numpy(columns[Columns.TERMINATEDS])
            if probs.ndim == 1:
                targets = reach_targets(costs, probs, terminateds, mask, gamma=self.gamma)
                self.safe_fraction[module_id] = float(1.0 - probs[mask].mean())
            else:  # K constraints: each column apart; a safe fraction each
                targets = np.stack([reach_targets(costs[:, k], probs[:, k], terminateds, mask, gamma=self.gamma)
                                    for k in range(probs.shape[1])], axis=-1)
                self.safe_fraction[module_id] = (1.0 - probs[mask].mean(0)).tolist()
            columns[REACH_PROBS] = probs_t
            columns[REACH_TARGETS] = torch.from_numpy(targets).to(probs_t.device)
        return batch
