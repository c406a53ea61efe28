"""OnPolicyTorchLearner: the on-policy family's learner (PPO-Lag, P3O, FOCOPS, CUP, RESPO, and the
trust-region base, families/trust_region/learner.py): RLlib's PPO learner with a cost critic, the
cost GAE, the cost window Ĵ_C, PPO's clipped surrogate and the KL early stop. No multiplier: PPO-Lag
adds one (families/on_policy/lagrangian.py), P3O a penalty. Source tags: [O] OmniSafe PPO /
PPOLag, [S] safety-starter-agents PPO-L, [R] RLlib.

One ``learner_group.update`` call is one iteration (what OmniSafe calls an epoch; an *epoch* below is
one pass over the iteration's batch):

1. before the gradient steps, Ĵ_C: the mean cost of the last ``cost_window`` completed episodes
   (this iteration's included), handed to :meth:`on_cost_window` (ν's step, with a multiplier:
   [O PPOLag._update: λ first, then the policy]);
2. the learner connector adds the cost GAE (cost_gae.py) and what a variant declares
   (:meth:`learner_pieces`);
3. each minibatch: PPO's clipped surrogate [R] on :meth:`policy_advantages` (A^R here; PPO-Lag's
   A = (A^R − ν·A^C)/(1 + ν) [O PPOLag._compute_adv_surrogate]), plus the reward critic's MSE [R]
   and the cost critic's MSE (no clipping: ``vf_clip_param=inf``), plus critic_l2·Σθ² over both
   critics [O use_critic_norm]; one optimizer per network (:meth:`optimizer_groups`), each with
   its own gradient-norm clip (RLlib's ``grad_clip`` is per optimizer) [O max_grad_norm];
4. the KL early stop [O]: after each epoch, KL(π_old ‖ π) over the whole batch; once it exceeds
   ``target_kl``, the remaining minibatches no longer step the policy (nor the critics, when
   ``kl_stop_critics``; then those minibatches are skipped whole, :meth:`skip_minibatch`, as
   OmniSafe breaks out of its epochs), or, with ``kl_stop_late`` [S],
   those after one more epoch. The check runs before the first
   minibatch that starts past an epoch's last row: RLlib's MiniBatchCyclicIterator fills every
   minibatch, so one that straddles an epoch's end trains before the check (OmniSafe's last
   minibatch of an epoch is short instead).

Two paths to the same update, bit for bit (``update_path``; tests/algorithms/test_update_path.py):
"rllib" is RLlib's own (its minibatch iterator, its PPO loss where a learner says so
(``RLLIB_LOSS``: PPO-Lag), torch's Adam, its clip); "fused", the default, runs the minibatches
inside one ``_update`` (constrained/minibatch_loop.py) and makes each step in fewer calls: RLlib's
loss terms computed here with their statistics on the reported minibatch only, the critics' L2
gradient added in closed form, the networks' clips and Adam steps each in one pass of foreach ops
(constrained/gradients.py, families/on_policy/optim.py): 1.7x faster at 64-row minibatches (docs/speed.md).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.ppo.ppo import (
    LEARNER_RESULTS_KL_KEY,
    LEARNER_RESULTS_VF_EXPLAINED_VAR_KEY,
    LEARNER_RESULTS_VF_LOSS_UNCLIPPED_KEY,
)
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import TorchDiagGaussian
from ray.rllib.core.learner.learner import ENTROPY_KEY, POLICY_LOSS_KEY, VF_LOSS_KEY
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.annotations import override
from ray.rllib.utils.torch_utils import explained_variance

from lac_rllib.constrained.cpus import learner_torch
from lac_rllib.constrained.gradients import clip_global_norms_, zero_non_finite_
from lac_rllib.constrained.metrics import (  # noqa: F401 (the learner's keys, declared with every other)
    COST_VF_LOSS,
    COST_WINDOW_MEAN,
    EPOCHS_TRAINED,
    KL_FULL_BATCH,
    NU,
    TS_CONSTRAINT_COSTS,
    TS_EPISODE_COSTS,
    per_constraint,
)
from lac_rllib.constrained.minibatch_loop import FusedMinibatchLoop
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES, COST_VALUE_TARGETS, CostGAE
from lac_rllib.families.on_policy.optim import ForeachAdam, step_adams

POLICY, CRITIC, COST_CRITIC = "policy", "critic", "cost_critic"  # optimizer names, one per network
#: The learner's own entry in its checkpointed state (RLlib's keeps the module, optimizers, metrics).
STATE_KEY = "on_policy"


@dataclasses.dataclass
class EpochProgress:
    """One update's progress through its epochs, for the KL early stop."""

    rows: int = 0  # rows of the minibatches trained on so far
    epoch: int = 0  # the epoch the current minibatch starts in (0-based)
    checked: int = 0  # epochs whose end was checked
    stopped_after: int | None = None  # the policy trains epochs [0, stopped_after) only
    kl: float = float("nan")  # KL at the last check


class OnPolicyTorchLearner(FusedMinibatchLoop, PPOTorchLearner):
    MINIBATCH_COLUMNS = (Columns.OBS, Columns.ACTIONS, Columns.ACTION_LOGP, Columns.LOSS_MASK,
                         Postprocessing.ADVANTAGES, Postprocessing.VALUE_TARGETS, COST_ADVANTAGES, COST_VALUE_TARGETS)

    @override(PPOTorchLearner)
    def build(self) -> None:
        learner_torch(self.config.torch_threads)  # threads; no NaN fill of fresh tensors (constrained/cpus.py)
        super().build()  # PPOLearner.build prepends RLlib's phantom step and appends its GAE
        self.cost_gae = CostGAE(gamma=self.config.cost_gamma, lambda_=self.config.lambda_,
                                standardize=self.config.standardize_cost_advantages)
        if self._learner_connector is not None and self.config.add_default_connectors_to_learner_pipeline:
            for where, piece in self.learner_pieces():  # the one place the pipeline is extended
                getattr(self._learner_connector, where)(piece)
        self.cost_windows = {mid: collections.deque(maxlen=self.config.get_config_for_module(mid).cost_window)
                             for mid in self.module.keys()}
        #: Ĵ_C of this iteration per module (None: no episode completed yet).
        self.cost_window_means: dict[str, float | None] = {}
        self.progress: dict[str, EpochProgress] = {}
        #: Each module's clip of this step: (its joint finiteness check, the gradients it saw).
        self._clip_checks: list[tuple[torch.Tensor, set]] = []

    def learner_pieces(self) -> list[tuple[str, Any]]:
        """The learner connector pieces this learner adds to RLlib's PPO pipeline, in order, each as
        ("append", piece): after RLlib's GAE, or ("prepend", piece): before RLlib's phantom step.
        The family's: the cost GAE, which needs the complete batch. A variant extends the list with
        pieces it built before ``super().build()``."""
        return [("append", self.cost_gae)]

    def optimizer_groups(self, module, config) -> dict[str, tuple[list, Any]]:
        """Optimizer name → (the networks it steps, its ``lr_or_lr_schedule``): one Adam per network
        [O]. A learner with another network (RESPO's reach critic) extends it; the trust-region
        base drops the policy's."""
        return {POLICY: ([module.encoder.actor_encoder, module.pi], config.policy_lr_or_schedule()),
                **self.critic_groups(module, config)}

    def critic_groups(self, module, config) -> dict[str, tuple[list, Any]]:
        """The critics' optimizers: V_R's (its encoder and head) and V_C's, at ``critic_lr``."""
        return {CRITIC: ([module.encoder.critic_encoder, module.vf], config.critic_lr),
                COST_CRITIC: ([module.cost_vf], config.critic_lr)}

    @override(PPOTorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        module = self.module[module_id].unwrapped()
        adam = ForeachAdam if config.update_path == "fused" else torch.optim.Adam  # the same steps
        for name, (parts, lr) in self.optimizer_groups(module, config).items():
            params = [p for part in parts for p in self.get_parameters(part)]
            self.register_optimizer(module_id=module_id, optimizer_name=name, optimizer=adam(params),
                                    params=params, lr_or_lr_schedule=lr)

    # ----- Ĵ_C, once per iteration before the gradient steps -----
    @override(PPOTorchLearner)
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)
        for mid in self.module.keys():
            several = self.config.get_config_for_module(mid).several_constraints
            # With K constraints each entry is an episode's K costs, Ĵ_C their mean: K values.
            costs = list(timesteps.get(TS_CONSTRAINT_COSTS if several else TS_EPISODE_COSTS) or [])
            window = self.cost_windows[mid]
            if window.maxlen is None:  # cost_window None: this iteration's episodes only [S]
                window.clear()
            window.extend(costs)
            j_c = None if not window else (np.mean(window, axis=0).tolist() if several else float(np.mean(window)))
            self.cost_window_means[mid] = j_c
            self.on_cost_window(mid, j_c)
            nu = self.module[mid].unwrapped().nu
            if several:  # each constraint's ν_k and Ĵ_Ck; ν itself reports the largest
                self.metrics.log_dict({
                    NU: float(nu.max()),
                    **{per_constraint(NU, n): float(v) for n, v in zip(several.names, nu.tolist())},
                    **{per_constraint(COST_WINDOW_MEAN, n): float("nan") if j_c is None else j_c[k]
                       for k, n in enumerate(several.names)}}, key=mid, window=1)
            else:
                self.metrics.log_dict({NU: float(nu), COST_WINDOW_MEAN: float("nan") if j_c is None else j_c},
                                      key=mid, window=1)
            self.progress[mid] = EpochProgress()

    def on_cost_window(self, module_id, j_c: float | None) -> None:
        """What Ĵ_C of this iteration does before the gradient steps (a multiplier's step: PPO-Lag's,
        lagrangian.py); nothing here. None: no episode completed yet."""

    # ----- losses -----
    #: Whether RLlib's own PPO loss is this learner's on RLlib's update path (PPO-Lag sets it: the
    #: reference its fused path is checked against bit for bit). Otherwise the loss is
    #: :meth:`fused_loss`, with the learner's own policy term, on both paths.
    RLLIB_LOSS = False

    def uses_fused_loss(self, config) -> bool:
        """Whether the loss is :meth:`fused_loss` (the critics' L2 then added to the gradients)."""
        return config.update_path == "fused" or not self.RLLIB_LOSS

    @override(PPOTorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        module = self.module[module_id].unwrapped()
        self.check_kl_at_epoch_end(module_id, config, module, minibatch_rows=len(batch[Columns.LOSS_MASK]))
        advantages = self.policy_advantages(config, module, batch)
        if self.uses_fused_loss(config):
            return self.fused_loss(module_id, config, module, batch, fwd_out, advantages)
        loss = super().compute_loss_for_module(module_id=module_id, config=config, fwd_out=fwd_out,
                                               batch={**batch, Postprocessing.ADVANTAGES: advantages})
        mask = batch[Columns.LOSS_MASK]
        cost_vf_loss = cost_critic_loss(module.compute_cost_values(batch), batch[COST_VALUE_TARGETS], mask)
        loss = loss + config.vf_loss_coeff * cost_vf_loss
        if config.critic_l2:
            loss = loss + config.critic_l2 * sum((p**2).sum() for p in critic_parameters(module))
        self.metrics.log_value((module_id, COST_VF_LOSS), cost_vf_loss.detach(), window=1)
        return loss

    def policy_advantages(self, config, module, batch) -> torch.Tensor:
        """The advantage the policy's surrogate weighs, per row: A^R [O PPO._compute_adv_surrogate]
        (a multiplier's learner weighs A^C in: lagrangian.py)."""
        return batch[Postprocessing.ADVANTAGES]

    def policy_loss(self, module_id, config, module, batch, logits, logp, advantages, masked_mean):
        """The policy's loss: per row (averaged over the real rows) and a term of the whole
        minibatch beside it (None: none). PPO's clipped surrogate, negated [R, O]:
        −min(r·A, clip(r, 1 − ε, 1 + ε)·A) with r = π(a|s)/π_old(a|s)."""
        logp_ratio = torch.exp(logp - batch[Columns.ACTION_LOGP])
        surrogate = torch.min(advantages * logp_ratio,
                              advantages * torch.clamp(logp_ratio, 1 - config.clip_param, 1 + config.clip_param))
        return -surrogate, None

    def fused_loss(self, module_id, config, module, batch, fwd_out, advantages) -> torch.Tensor:
        """:meth:`compute_loss_for_module`'s loss on the fused path: RLlib's PPO loss
        (ppo_torch_learner.py, the arithmetic of its terms kept) on the Lagrangian advantage
        [O PPOLag._compute_adv_surrogate], plus the cost critic's MSE; the critics' L2
        [O use_critic_norm] is left to :meth:`compute_gradients`. RLlib's loss is computed here
        rather than called: PPO-Lag pins what it leaves out (no KL penalty, entropy_coeff 0 [O, S],
        the value clip at inf unless set), and its statistics are computed on the minibatch whose
        values are reported only (``reports_minibatch``; RLlib logs every minibatch with window 1,
        keeping the last)."""
        mask = batch[Columns.LOSS_MASK]
        num_valid = torch.sum(mask)
        rows = mask.nonzero().squeeze(-1)  # the real rows, found once: x[rows] is x[mask]

        def masked_mean(x: torch.Tensor) -> torch.Tensor:  # RLlib's possibly_masked_mean
            return torch.sum(x[rows]) / num_valid

        dist_cls, logits = module.get_train_action_dist_cls(), fwd_out[Columns.ACTION_DIST_INPUTS]
        logp = (gaussian_logp(logits, batch[Columns.ACTIONS]) if dist_cls is TorchDiagGaussian
                else dist_cls.from_logits(logits).logp(batch[Columns.ACTIONS]))
        policy_rows, policy_term = self.policy_loss(module_id, config, module, batch, logits, logp,
                                                    advantages, masked_mean)
        values = module.compute_values(batch, embeddings=fwd_out.get(Columns.EMBEDDINGS))
        vf_loss = torch.pow(values - batch[Postprocessing.VALUE_TARGETS], 2.0)
        # A square is >= 0, so clamp(·, 0, inf) is the identity, forward and backward.
        vf_loss_clipped = vf_loss if math.isinf(config.vf_clip_param) else torch.clamp(vf_loss, 0, config.vf_clip_param)
        per_row = policy_rows + config.vf_loss_coeff * vf_loss_clipped
        if config.entropy_coeff:  # 0 in every preset: RLlib's term is then 0·H (its gradient 0)
            coeff = self.entropy_coeff_schedulers_per_module[module_id].get_current_value()
            per_row = per_row - coeff * dist_cls.from_logits(logits).entropy()
        loss = masked_mean(per_row)
        if policy_term is not None:
            loss = loss + policy_term
        cost_vf_loss = cost_critic_loss(module.compute_cost_values(batch), batch[COST_VALUE_TARGETS], rows)
        loss = loss + config.vf_loss_coeff * cost_vf_loss
        # critic_l2·Σθ² [O use_critic_norm] is not in this graph: compute_gradients adds its
        # gradient critic_l2·2θ after the backward pass (its value to the reported loss only).
        if self.reports_minibatch:
            with torch.no_grad():
                self.metrics.log_dict({
                    POLICY_LOSS_KEY: masked_mean(policy_rows) + (0.0 if policy_term is None else policy_term),
                    VF_LOSS_KEY: masked_mean(vf_loss_clipped),
                    LEARNER_RESULTS_VF_LOSS_UNCLIPPED_KEY: masked_mean(vf_loss),
                    LEARNER_RESULTS_VF_EXPLAINED_VAR_KEY: explained_variance(
                        batch[Postprocessing.VALUE_TARGETS], values),
                    ENTROPY_KEY: masked_mean(dist_cls.from_logits(logits).entropy()),
                    LEARNER_RESULTS_KL_KEY: torch.tensor(0.0),
                    COST_VF_LOSS: cost_vf_loss,
                }, key=module_id, window=1)
                l2 = config.critic_l2 * sum((p**2).sum() for p in critic_parameters(module)) if config.critic_l2 else 0
            loss = loss + l2  # a constant here: the reported loss is the whole loss, its gradient unchanged
        return loss

    # ----- the KL early stop -----
    def check_kl_at_epoch_end(self, module_id, config, module, *, minibatch_rows: int) -> None:
        """Before a minibatch's step: if an epoch ended since the last check, measure KL(π_old ‖ π)
        on the whole batch [O] and stop the policy's steps if it exceeds ``target_kl``."""
        progress = self.progress.setdefault(module_id, EpochProgress())
        whole = self.cost_gae.last_batch.get(module_id)
        if whole is not None:
            progress.epoch = progress.rows // len(whole[Columns.LOSS_MASK])
            if config.target_kl is not None and progress.stopped_after is None and progress.epoch > progress.checked:
                progress.checked, progress.kl = progress.epoch, full_batch_kl(module, whole)
                if progress.kl > config.target_kl:
                    # [O] breaks before the next epoch; [S] checks before a step and still takes it.
                    progress.stopped_after = progress.epoch + int(config.kl_stop_late)
        progress.rows += minibatch_rows

    @override(FusedMinibatchLoop)
    def skip_minibatch(self, rows: dict[str, int]) -> bool:
        """Once the KL early stop has stopped every network of every module (``kl_stop_critics``), a
        minibatch steps nothing [O breaks out of its epochs instead]: its rows are counted, as
        :meth:`check_kl_at_epoch_end` would, and its forward pass and losses skipped."""
        epochs = {}
        for mid in rows:
            progress, whole = self.progress.get(mid), self.cost_gae.last_batch.get(mid)
            if progress is None or whole is None:
                return False
            size = len(whole[Columns.LOSS_MASK])
            epochs[mid] = progress.rows // size
            if not self.idle(mid, epochs[mid], (progress.rows + rows[mid]) // size):
                return False
        for mid, n in rows.items():
            self.progress[mid].epoch = epochs[mid]
            self.progress[mid].rows += n
        return True

    def idle(self, module_id, epoch: int, end_epoch: int) -> bool:
        """Whether a minibatch starting in ``epoch`` (its end in ``end_epoch``) would step none of
        ``module_id``'s networks and check nothing: the KL early stop has stopped them all for the rest
        of the update."""
        progress = self.progress[module_id]
        return (progress.stopped_after is not None and epoch >= progress.stopped_after
                and self.config.get_config_for_module(module_id).kl_stop_critics)

    def stopped_optimizers(self, module_id) -> tuple[str, ...]:
        progress = self.progress.get(module_id)
        if progress is None or progress.stopped_after is None or progress.epoch < progress.stopped_after:
            return ()
        if self.config.get_config_for_module(module_id).kl_stop_critics:
            return self.optimizer_names(module_id)
        return (POLICY,)

    def optimizer_names(self, module_id) -> tuple[str, ...]:
        """Every optimizer of ``module_id`` (:meth:`optimizer_groups`), in registration order."""
        return tuple(name for name, _ in self.get_optimizers_for_module(module_id))

    @override(PPOTorchLearner)
    def compute_gradients(self, loss_per_module, **kwargs):
        if all(self.stopped_optimizers(mid) == self.optimizer_names(mid) for mid in self.module.keys()):
            # Every network has stopped for this iteration: skip the backward pass.
            for mid in self.module.keys():
                for _, optim in self.get_optimizers_for_module(mid):
                    optim.zero_grad(set_to_none=True)
            return {}
        grads = super().compute_gradients(loss_per_module, **kwargs)
        for mid in loss_per_module:
            config = self.config.get_config_for_module(mid)
            if self.uses_fused_loss(config) and config.critic_l2:
                add_l2_gradient_(critic_parameters(self.module[mid].unwrapped()), config.critic_l2)
        return grads

    @override(PPOTorchLearner)
    def postprocess_gradients_for_module(self, *, module_id, config, module_gradients_dict):
        """Each optimizer's gradients clipped to a global norm of ``grad_clip`` [O max_grad_norm]
        and its norm logged, as RLlib's Learner does; on the fused path the three clips in one pass
        (:func:`clip_global_norms_`, RLlib's arithmetic)."""
        if config.update_path != "fused":
            return super().postprocess_gradients_for_module(module_id=module_id, config=config,
                                                            module_gradients_dict=module_gradients_dict)
        if not config.grad_clip:  # None or 0: RLlib's Learner does not clip either
            return dict(module_gradients_dict)
        named = [(name, self.filter_param_dict_for_optimizer(param_dict=module_gradients_dict, optimizer=optim))
                 for name, optim in self.get_optimizers_for_module(module_id)]
        finite = []
        norms = clip_global_norms_([list(grads.values()) for _, grads in named], config.grad_clip, finite)
        self._clip_checks.append((finite[0], {ref for _, grads in named for ref in grads}))
        if self.reports_minibatch:
            for (name, _), norm in zip(named, norms):
                self.metrics.log_value((module_id, f"gradients_{name}_global_norm"), norm, window=1)
        return {ref: g for _, grads in named for ref, g in grads.items()}

    @override(PPOTorchLearner)
    def apply_gradients(self, gradients_dict) -> None:
        """The KL early stop's networks left out (their .grad None: Adam skips them, moments
        included), RLlib's NaN/inf guard, then the optimizers' steps: TorchLearner's, or on the
        fused path every network's Adam in one pass (:func:`step_adams`, the same steps)."""
        grads = dict(gradients_dict)
        for mid in self.module.keys():
            for name in self.stopped_optimizers(mid):
                optim = self.get_optimizer(mid, name)
                for pid in self.filter_param_dict_for_optimizer(grads, optim):
                    del grads[pid]
                optim.zero_grad(set_to_none=True)
        # RLlib's NaN/inf guard, one test for all (constrained/gradients.py), read off the clip's
        # norms when the clip saw every gradient left.
        checks, self._clip_checks = self._clip_checks, []
        covered = set().union(*(refs for _, refs in checks)) if checks else set()
        finite = None
        if checks and all(ref in covered for ref, g in grads.items() if g is not None):
            finite = checks[0][0] if len(checks) == 1 else torch.stack([f for f, _ in checks]).all()
        zero_non_finite_(grads, finite)
        if self.config.update_path != "fused":
            super().apply_gradients(grads)
            return
        for param, grad in grads.items():  # TorchLearner's own step: .grad ← the gradient (refs are params)
            param.grad = grad
        step_adams([optim for mid in self.module.keys() for _, optim in self.get_optimizers_for_module(mid)])

    @override(PPOTorchLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().after_gradient_based_update(timesteps=timesteps)  # steps the lr schedules
        for mid, progress in self.progress.items():
            epochs = self.config.get_config_for_module(mid).num_epochs
            epochs = epochs if progress.stopped_after is None else min(progress.stopped_after, epochs)
            self.metrics.log_dict({EPOCHS_TRAINED: epochs, KL_FULL_BATCH: progress.kl}, key=mid, window=1)

    # ----- state: the cost windows (a multiplier's rule beside them: lagrangian.py) -----
    @override(PPOTorchLearner)
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[STATE_KEY] = {mid: {"cost_window": list(window)} for mid, window in self.cost_windows.items()}
        return state

    @override(PPOTorchLearner)
    def set_state(self, state) -> None:
        super().set_state(state)
        for mid, saved in state.get(STATE_KEY, {}).items():
            self.cost_windows[mid].clear()
            self.cost_windows[mid].extend(saved["cost_window"])


@torch.no_grad()
def full_batch_kl(module, columns: dict) -> float:
    """Mean KL(π_old ‖ π) over the real rows of a whole batch (π_old: the behaviour policy's inputs)."""
    dist = module.get_train_action_dist_cls()
    old = dist.from_logits(columns[Columns.ACTION_DIST_INPUTS])
    new = dist.from_logits(module.action_dist_inputs(columns[Columns.OBS]))
    return float(old.kl(new)[columns[Columns.LOSS_MASK]].mean())


def cost_critic_loss(values: torch.Tensor, targets: torch.Tensor, rows) -> torch.Tensor:
    """The cost critic's MSE over the real ``rows`` (a mask or their indices); with K constraints
    (values (B, K)) the sum of the K critics' MSEs, each critic's loss as if it were alone."""
    squared = (values - targets) ** 2
    return squared[rows].mean() if squared.dim() == 1 else squared[rows].mean(0).sum()


def critic_parameters(module) -> list:
    """The parameters of both critics, V_R's encoder and head and V_C (the L2 term's)."""
    return [p for net in (module.encoder.critic_encoder, module.vf, module.cost_vf) for p in net.parameters()]


@torch.no_grad()
def add_l2_gradient_(params: list, coeff: float) -> None:
    """p.grad += coeff·2p for every p: the gradient of coeff·Σ p² as autograd computes it
    (pow's backward 2·p times the coefficient the product's backward passes down: one rounding,
    the same as (2·coeff)·p's, a power of two apart; then added to the loss's own gradient, an
    addition in either order)."""
    params = [p for p in params if p.grad is not None]
    if params:
        # The factor as a 0-d float32 tensor: the kernels cast a number to float32 first (the same
        # product), and on CPU a Python number is wrapped into a tensor again for each parameter.
        factor = torch.tensor(2.0 * coeff, dtype=params[0].dtype)
        torch._foreach_add_([p.grad for p in params], torch._foreach_mul(params, factor))


def gaussian_logp(logits: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """``TorchDiagGaussian.from_logits(logits).logp(actions)`` op for op (torch's
    ``Normal.log_prob`` summed over the action), without building the distribution objects."""
    loc, log_std = logits.chunk(2, dim=-1)
    scale = log_std.exp()
    var = scale**2
    return (-((actions - loc) ** 2) / (2 * var) - scale.log() - math.log(math.sqrt(2 * math.pi))).sum(-1)
