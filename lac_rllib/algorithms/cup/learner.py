"""CUPTorchLearner: PPO-Lag's learner with CUP's two stages in one update call. Source tags:
[O] OmniSafe cup.py (``CUP._update``, ``CUP._loss_pi_cost``), [D] ours.

One ``update`` call is one iteration; ν first takes PPO-Lag's step on the cost window [O], then:

1. **stage 1, policy improvement**: the first ``num_epochs`` epochs are PPO-Lag's, on A = A^R: the
   clipped surrogate, both critics, the KL early stop on KL(π_old ‖ π) [O ``super()._update()``;
   CUP inherits PPO's ``_compute_adv_surrogate``, which returns A^R, so ν is not in this stage];
2. **stage 2, projection**: ``projection_epochs`` more epochs over the same batch (same A^C, same
   behaviour log-probabilities) step the policy only, on [O ``_loss_pi_cost``]

       L(θ) = mean over the real rows of  ν·(1 − γλ)/(1 − γ)·r(s, a)·A^C(s, a) + KL(π_θ ‖ π_stage1)[s],

   r = π_θ(a|s)/π_old(a|s) with π_old the behaviour policy (``ACTION_LOGP``), π_stage1 the policy
   at the switch: its distribution inputs on the whole batch are taken once, and each minibatch
   reads its rows by ``ROW_INDEX`` (row_index.py). After each stage-2 epoch, KL(π_stage1 ‖ π) over
   the whole batch above ``target_kl`` ends the projection [O]. The policy's clip and Adam are
   stage 1's [O: the same ``actor_optimizer``, ``max_grad_norm``].

The switch goes by the row count, as PPO-Lag's KL check: the first minibatch that starts past
stage 1's last row is stage 2's. A minibatch straddling the switch trains on stage 1's loss.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import TorchDiagGaussian
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.cup.config import PROJECTION_EPOCHS, PROJECTION_KL, PROJECTION_LOSS
from lac_rllib.algorithms.cup.row_index import ROW_INDEX, AddRowIndex
from lac_rllib.algorithms.ppo_lag.learner import PPOLagTorchLearner
from lac_rllib.constrained.lagrange import nu_weighted
from lac_rllib.constrained.minibatch_loop import TS_MINIBATCHES
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.on_policy.learner import POLICY, gaussian_logp
from lac_rllib.families.on_policy.projection import kl_to_reference


@dataclasses.dataclass
class Projection:
    """Stage 2's progress in one update (the epochs are counted from the update's start)."""

    first_epoch: int  # stage 1's epochs: stage 2 starts at this epoch
    epochs: int  # stage 2's epochs
    reference: torch.Tensor | None = None  # π_stage1's distribution inputs on the whole batch
    checked: int = 0  # epochs whose end was checked
    stopped_after: int | None = None  # the policy trains epochs [first_epoch, stopped_after) only
    kl: float = float("nan")  # KL(π_stage1 ‖ π) at the last check


class CUPTorchLearner(PPOLagTorchLearner):
    RLLIB_LOSS = False
    MINIBATCH_COLUMNS = (*PPOLagTorchLearner.MINIBATCH_COLUMNS, ROW_INDEX)

    @override(PPOLagTorchLearner)
    def build(self) -> None:
        super().build()
        self.stage_epochs = (self.config.num_epochs, self.config.stage2_epochs)
        self.projections: dict[str, Projection] = {}

    @override(PPOLagTorchLearner)
    def learner_pieces(self) -> list:
        """PPO-Lag's, then each row's index in the batch, after the cost GAE whose last_batch it numbers."""
        return [*super().learner_pieces(), ("append", AddRowIndex())]

    # ----- both stages in one call -----
    @override(PPOLagTorchLearner)
    def update(self, *args, timesteps: dict | None = None, num_epochs: int = 1, **kwargs):
        """Stage 1's epochs as asked (``num_epochs``, or the fused loop's plan in ``timesteps``),
        then stage 2's: the call runs both, so the learner connector (the cost GAE) runs once."""
        timesteps = dict(timesteps or {})
        extra = self.config.stage2_epochs
        plan = timesteps.get(TS_MINIBATCHES)
        if plan is not None:  # the fused loop: one _update over the whole batch, the plan inside
            self.stage_epochs = (plan["num_epochs"], extra)
            timesteps[TS_MINIBATCHES] = {**plan, "num_epochs": plan["num_epochs"] + extra}
        else:
            self.stage_epochs, num_epochs = (num_epochs, extra), num_epochs + extra
        return super().update(*args, timesteps=timesteps, num_epochs=num_epochs, **kwargs)

    @override(PPOLagTorchLearner)
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # ν's step first [O CUP._update]
        first, epochs = self.stage_epochs
        self.projections = {mid: Projection(first_epoch=first, epochs=epochs) for mid in self.module.keys()}

    # ----- losses -----
    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """Stage 1's advantage: A^R alone [O CUP inherits PPO._compute_adv_surrogate]."""
        return batch[Postprocessing.ADVANTAGES]

    @override(PPOLagTorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        module = self.module[module_id].unwrapped()
        self.check_kl_at_epoch_end(module_id, config, module, minibatch_rows=len(batch[Columns.LOSS_MASK]))
        projection = self.projections[module_id]
        if projection.reference is not None:
            return self.projection_loss(module_id, config, module, batch, fwd_out, projection.reference)
        whole = self.cost_gae.last_batch[module_id]
        if self.progress[module_id].rows // len(whole[Columns.LOSS_MASK]) >= projection.first_epoch:
            # Stage 1's last minibatch reports its statistics (the fused loop: the update's last only).
            self.reports_minibatch = True
        return self.fused_loss(module_id, config, module, batch, fwd_out, self.policy_advantages(config, module, batch))

    def projection_loss(self, module_id, config, module, batch, fwd_out, reference) -> torch.Tensor:
        """Stage 2's loss (the module docstring) [O CUP._loss_pi_cost], on a minibatch whose rows
        in ``reference`` (π_stage1's distribution inputs on the whole batch) are ``ROW_INDEX``."""
        rows = batch[Columns.LOSS_MASK].nonzero().squeeze(-1)
        dist_cls, logits = module.get_train_action_dist_cls(), fwd_out[Columns.ACTION_DIST_INPUTS]
        logp = (gaussian_logp(logits, batch[Columns.ACTIONS]) if dist_cls is TorchDiagGaussian
                else dist_cls.from_logits(logits).logp(batch[Columns.ACTIONS]))
        ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])  # against the behaviour policy [O logp]
        kl = kl_to_reference(dist_cls, logits, reference.index_select(0, batch[ROW_INDEX]))  # KL(π_θ ‖ π_stage1)
        coef = (1.0 - config.gamma * config.lambda_) / (1.0 - config.gamma)  # [O: gamma, lam]
        nu = module.nu.detach()
        if nu.dim() == 0:
            loss = (nu * coef * ratio * batch[COST_ADVANTAGES] + kl)[rows].mean()
        else:  # K constraints: Σ_k ν_k·A^C_k in place of ν·A^C
            loss = (coef * ratio * nu_weighted(nu, batch[COST_ADVANTAGES]) + kl)[rows].mean()
        if self.reports_minibatch:
            self.metrics.log_value((module_id, PROJECTION_LOSS), loss.detach(), window=1)
        return loss

    # ----- the switch and stage 2's KL stop -----
    def check_kl_at_epoch_end(self, module_id, config, module, *, minibatch_rows: int) -> None:
        """Stage 1: PPO-Lag's check (its last one at the switch). At the switch, π_stage1's
        snapshot; in stage 2, after each epoch, KL(π_stage1 ‖ π) on the whole batch [O]."""
        projection, whole = self.projections[module_id], self.cost_gae.last_batch.get(module_id)
        if whole is None:
            raise RuntimeError("CUP's stages need the whole batch its learner connector's cost GAE keeps")
        progress = self.progress[module_id]
        if projection.reference is None:
            super().check_kl_at_epoch_end(module_id, config, module, minibatch_rows=minibatch_rows)
            if progress.epoch >= projection.first_epoch:  # this minibatch starts stage 2
                with torch.no_grad():
                    projection.reference = module.action_dist_inputs(whole[Columns.OBS])
                projection.checked = progress.epoch
            return
        progress.epoch = progress.rows // len(whole[Columns.LOSS_MASK])
        if config.target_kl is not None and projection.stopped_after is None and progress.epoch > projection.checked:
            projection.checked, projection.kl = progress.epoch, kl_from_reference(module, whole, projection.reference)
            if projection.kl > config.target_kl:
                projection.stopped_after = progress.epoch  # [O] breaks before the next epoch
        progress.rows += minibatch_rows

    @override(PPOLagTorchLearner)
    def idle(self, module_id, epoch: int, end_epoch: int) -> bool:
        """Stage 1: PPO-Lag's stop, up to stage 1's last minibatch (which reports stage 1's
        statistics; the next takes π_stage1's snapshot). Stage 2: once its own KL stop has ended the
        projection (the critics never step there)."""
        projection = self.projections[module_id]
        if projection.reference is None:
            return end_epoch < projection.first_epoch and super().idle(module_id, epoch, end_epoch)
        return projection.stopped_after is not None and epoch >= projection.stopped_after

    def stopped_optimizers(self, module_id) -> tuple[str, ...]:
        """Stage 1: PPO-Lag's KL stop. Stage 2 never steps the critics [O: actor_optimizer only],
        nor the policy once its own KL stop has ended the projection."""
        projection = self.projections.get(module_id)
        if projection is None or projection.reference is None:
            return super().stopped_optimizers(module_id)
        stopped = projection.stopped_after is not None and self.progress[module_id].epoch >= projection.stopped_after
        critics = tuple(name for name in self.optimizer_names(module_id) if name != POLICY)
        return self.optimizer_names(module_id) if stopped else critics

    @override(PPOLagTorchLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().after_gradient_based_update(timesteps=timesteps)
        for mid, projection in self.projections.items():
            if projection.reference is None:  # stage 2 never started (no minibatch past stage 1)
                epochs = 0
            elif projection.stopped_after is None:
                epochs = projection.epochs
                # Report the drift the projection ended with (its last epoch has no check after it).
                projection.kl = kl_from_reference(self.module[mid].unwrapped(), self.cost_gae.last_batch[mid],
                                                  projection.reference)
            else:
                epochs = projection.stopped_after - projection.first_epoch
            self.metrics.log_dict({PROJECTION_EPOCHS: epochs, PROJECTION_KL: projection.kl}, key=mid, window=1)
        self.projections = {}  # the snapshot is this update's


@torch.no_grad()
def kl_from_reference(module, columns: dict, reference: torch.Tensor) -> float:
    """Mean KL(π_ref ‖ π) over the real rows of a whole batch, π_ref given by its distribution inputs."""
    dist = module.get_train_action_dist_cls()
    new = dist.from_logits(module.action_dist_inputs(columns[Columns.OBS]))
    return float(dist.from_logits(reference).kl(new)[columns[Columns.LOSS_MASK]].mean())
