"""Cost GAE: the learner connector that gives the on-policy family its cost advantages and cost value
targets.

RLlib's PPO learner pipeline (PPOLearner.build) starts with ``AddOneTsToEpisodesAndTruncate``
(each episode chunk gets a phantom last row, masked out by ``LOSS_MASK``, whose value bootstraps
a cut chunk) and ends with ``GeneralAdvantageEstimation`` (rewards only). :class:`CostGAE` comes
after it and does the same for costs (the ``costs`` column of ``AddCostsFromInfos``) with V_C:

    δ_t = c_t + γ_C·(1 − terminated_t)·V_C(s_{t+1}) − V_C(s_t),   A^C_t = Σ_k (γ_C·λ)^k δ_{t+k}

within a chunk (GAE, Schulman et al. 2016, eq. 16, by RLlib's ``compute_value_targets``, which
cuts the sum at chunk ends and bootstraps there), target_t = A^C_t + V_C(s_t). Then, on the real
rows (``LOSS_MASK``) only:

- A^C is centred, not rescaled [O onpolicy_buffer.get; S buffer.get], so ν·A^C keeps the cost's scale
  (``standardize``: also rescaled, as FOCOPS's own code does [F]);
- A^R, which RLlib standardised over every row including the phantom ones, is standardised again
  over the real rows: (A − mean)/(std + 1e-8) [O]. An affine map of A^R, so this equals
  standardising the raw GAE advantages over the real rows.

The phantom row repeats the chunk's last info, so ``AddCostsFromInfos`` gave it that step's cost:
it is set to 0 here, and the phantom rows' advantages too (the loss masks them anyway).

With K constraints the costs, V_C, A^C and the targets are (B, K): each constraint's column goes
through the same GAE apart, with its own critic (and is centred apart).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override
from ray.rllib.utils.numpy import convert_to_numpy
from ray.rllib.utils.postprocessing.value_predictions import compute_value_targets

from lac_rllib.constrained.costs import COSTS

# The train batch's cost columns, row-aligned with ``costs``.
COST_ADVANTAGES = "cost_advantages"  # A^C, centred over the real rows
COST_VALUE_TARGETS = "cost_value_targets"  # the cost critic's regression target
#: The columns the KL early stop needs from the whole batch.
KL_COLUMNS = (Columns.OBS, Columns.ACTION_DIST_INPUTS, Columns.LOSS_MASK)


def cost_gae(costs, values, terminateds, truncateds, mask, *, gamma: float, lambda_: float, standardize: bool = False):
    """(centred A^C, V_C targets) of rows in episode-chunk order (numpy, one entry per row); with
    ``standardize`` A^C is also divided by its std + 1e-8 [F data_generator.py].

    ``costs`` of phantom rows (``mask`` False) are ignored (taken as 0); their outputs are 0."""
    mask = np.asarray(mask, dtype=bool)
    costs = np.where(mask, costs, 0.0).astype(np.float32)
    targets = compute_value_targets(values=values, rewards=costs, terminateds=terminateds, truncateds=truncateds,
                                    gamma=gamma, lambda_=lambda_)
    advantages = targets - values
    if standardize:
        return standardize_on_mask(advantages, mask), np.where(mask, targets, 0.0).astype(np.float32)
    advantages = np.where(mask, advantages - advantages[mask].mean(), 0.0).astype(np.float32)
    return advantages, np.where(mask, targets, 0.0).astype(np.float32)


def standardize_on_mask(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(x − mean)/(std + 1e-8) over the rows of ``mask`` [O], 0 elsewhere."""
    real = x[mask]
    return np.where(mask, (x - real.mean()) / (real.std() + 1e-8), 0.0).astype(np.float32)


class CostGAE(ConnectorV2):
    """Writes ``COST_ADVANTAGES`` and ``COST_VALUE_TARGETS``, zeroes the phantom rows' ``costs`` and
    restandardises ``ADVANTAGES`` over the real rows (see the module docstring).

    It keeps the observations, behaviour-policy inputs and mask of the last batch it completed
    (``last_batch``: module id → those columns): the learner's KL early stop measures the policy's
    drift on the whole batch (learner.py). A learner that needs more of the whole batch (the
    trust-region step: actions, log-probabilities, both advantages) sets ``kept_columns``."""

    #: The columns of the whole batch ``last_batch`` keeps (the KL early stop's).
    kept_columns: tuple[str, ...] = KL_COLUMNS

    def __init__(self, input_observation_space=None, input_action_space=None, *, gamma: float, lambda_: float,
                 standardize: bool = False):
        super().__init__(input_observation_space, input_action_space)
        self.gamma, self.lambda_, self.standardize = float(gamma), float(lambda_), bool(standardize)
        self.last_batch: dict[str, dict[str, Any]] = {}

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        for module_id, columns in batch.items():
            module = rl_module[module_id].unwrapped()
            if not hasattr(module, "compute_cost_values") or COSTS not in columns:
                continue
            if module.is_stateful():
                raise ValueError("the cost GAE supports stateless modules only (rows in episode order)")
            with torch.no_grad():
                values_t = module.compute_cost_values(columns)
            values = convert_to_numpy(values_t)
            mask = convert_to_numpy(columns[Columns.LOSS_MASK]).astype(bool)
            costs = convert_to_numpy(columns[COSTS])
            gae = functools.partial(cost_gae, terminateds=convert_to_numpy(columns[Columns.TERMINATEDS]),
                                    truncateds=convert_to_numpy(columns[Columns.TRUNCATEDS]), mask=mask,
                                    gamma=self.gamma, lambda_=self.lambda_, standardize=self.standardize)
            if costs.ndim == 1:
                advantages, targets = gae(costs, values)
            else:  # K constraints: each column apart
                per = [gae(costs[:, k], values[:, k]) for k in range(costs.shape[1])]
                advantages, targets = (np.stack(x, axis=-1) for x in zip(*per))
            out = {
                COSTS: np.where(mask.reshape(-1, *[1] * (costs.ndim - 1)), costs, 0.0).astype(np.float32),
                COST_ADVANTAGES: advantages,
                COST_VALUE_TARGETS: targets,
                Postprocessing.ADVANTAGES: standardize_on_mask(convert_to_numpy(columns[Postprocessing.ADVANTAGES]),
                                                               mask),
            }
            columns.update({k: torch.from_numpy(v).to(values_t.device) for k, v in out.items()})
            self.last_batch[module_id] = {k: columns[k] for k in self.kept_columns}
        return batch
