"""LACTorchLearner: the losses of LAC (eqs. 12-13, 15-16), the ν update (eq. 14) and Polyak.

One ``learner_group.update`` call makes a whole pass of minibatches over the replay buffer
(Algorithm 2, lines 6-14); per minibatch: critic step, actor step, Polyak step of all targets
(from the first actor update on [C]). Around the pass: ν's projected step under its bound before
it (eq. 14, docs/spec.md §4), the learning-rate schedules and the next bound after it.

Each equation is written out, in the notation of docs/spec.md, where it is computed: the critic
targets (13) in :func:`critic_targets`; the critic loss (12) and the actor loss (15-16) in
``compute_loss_for_module``; ν's step (14) in ``lagrange_step`` and its bound ν_max in
``after_gradient_based_update``; Polyak in ``apply_gradients``. Methods marked ``@override`` are
RLlib's hooks; the others are LAC's own.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.connectors.common.batch_individual_items import BatchIndividualItems
from ray.rllib.connectors.learner import (
    AddNextObservationsFromEpisodesToTrainBatch,
    AddObservationsFromEpisodesToBatch,
)
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.learner.utils import update_target_network
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.lac import module as M
from lac_rllib.algorithms.lac.networks import cost_rows, gaussian_kl, gaussian_log_prob, reward_rows
from lac_rllib.constrained.costs import COSTS, AddCostsFromInfos, ShuffleRows

CRITIC, ACTOR = "critic", "actor"  # optimizer names, one per loss

# ----- Metric keys, declared once (as RLlib's sac_learner declares QF_LOSS_KEY) -----
# Logged per module (results["learners"][module_id]); the last minibatch's value unless noted.
CRITIC_LOSS, ACTOR_LOSS = "critic_loss", "actor_loss"  # L_Q (eq. 12), L_A (eqs. 15-16)
ACTOR_NLL, ACTOR_KL = "actor_nll", "actor_kl"  # L_A's terms: −mean log π_φ(ã|s*), mean KL(π_φ ‖ π_φ')
Q_REWARD_MEAN, Q_COST_MEAN = "q_reward_mean", "q_cost_mean"  # mean online Q_R(s, a), Q_C(s, a)
# ν (the algorithm reports it at the top level too, under the same key) and the bound ν_max it was
# held under this iteration; the iteration's mean targets ȳ_R, ȳ_C (they set the next bound).
NU, NU_MAX = "nu", "nu_max"
TARGET_REWARD_MEAN, TARGET_COST_MEAN = "target_reward_mean", "target_cost_mean"
# Chain health (docs/spec.md §1): means over the last HEALTH_WINDOW minibatches, about one
# iteration (one pass over a full 50k buffer is 195 minibatches of 256).
HEALTH_WINDOW = 200
LANGEVIN_ENERGY_DROP = "langevin_energy_drop"  # E(s, ã_0) − E(s, ã_T)
LANGEVIN_DISPLACEMENT = "langevin_displacement"  # ‖ã_T − ã_0‖₂
LANGEVIN_GRAD_NORM = "langevin_grad_norm"  # ‖∇_a E‖₂ per sample, before the clip
LANGEVIN_CLIP_FRACTION = "langevin_clip_fraction"  # fraction of chain steps the clip bound
LANGEVIN_AT_BOUND = "langevin_at_bound"  # fraction of end points ã_T on an action bound
ACTOR_STD_MEAN = "actor_std_mean"  # mean σ of π_φ
CHAIN_HEALTH_KEYS = (LANGEVIN_ENERGY_DROP, LANGEVIN_DISPLACEMENT, LANGEVIN_GRAD_NORM,
                     LANGEVIN_CLIP_FRACTION, LANGEVIN_AT_BOUND, ACTOR_STD_MEAN)
#: What the trainer and the sweep report per iteration from the learner's results.
REPORTED_KEYS = (CRITIC_LOSS, ACTOR_LOSS, ACTOR_NLL, ACTOR_KL, Q_REWARD_MEAN, Q_COST_MEAN,
                 TARGET_REWARD_MEAN, TARGET_COST_MEAN, NU_MAX, *CHAIN_HEALTH_KEYS)
# Keys the algorithm passes in ``timesteps`` to every update call.
TS_EPISODE_COST, TS_ITERATION = "lac_episode_cost", "lac_training_iteration"


def critic_targets(batch, q_next: torch.Tensor, n_reward: int, config) -> tuple[torch.Tensor, torch.Tensor]:
    """The critic targets, eq. (13) with clipped double-Q (docs/spec.md §2):

        y_R = k_r·r + γ·(1 − d)·min_j Q'_Rj(s', ã')
        y_C =     c + γ_C·(1 − d)·max_j Q'_Cj(s', ã')

    ``q_next`` is the target ensemble Q' at (s', ã') (E, B); k_r = ``reward_scale``, γ_C =
    ``cost_gamma``. d = terminated: time-limit truncation bootstraps [D] unless
    ``bootstrap_on_truncation`` is off, d = terminated ∨ truncated, which reproduces [C]."""
    done = batch[Columns.TERMINATEDS].float()
    if not config.bootstrap_on_truncation:
        done = torch.maximum(done, batch[Columns.TRUNCATEDS].float())
    min_q_r = reward_rows(q_next, n_reward).min(0).values
    max_q_c = cost_rows(q_next, n_reward).max(0).values
    y_r = config.reward_scale * batch[Columns.REWARDS] + config.gamma * (1 - done) * min_q_r
    y_c = batch[COSTS] + config.cost_gamma * (1 - done) * max_q_c
    return y_r, y_c


class LACTorchLearner(TorchLearner):
    @override(TorchLearner)
    def build(self) -> None:
        torch.set_num_threads(self.config.torch_threads)
        super().build()
        self.module.foreach_module(
            lambda mid, mod: mod.make_target_networks() if isinstance(mod, TargetNetworkAPI) else None
        )
        # s' for the critic targets, then the cost of each row (docs/dependencies.md, "The cost column": this order).
        self._learner_connector.insert_after(
            AddObservationsFromEpisodesToBatch, AddNextObservationsFromEpisodesToTrainBatch()
        )
        self._learner_connector.insert_after(AddNextObservationsFromEpisodesToTrainBatch, AddCostsFromInfos())
        self._learner_connector.insert_after(BatchIndividualItems, ShuffleRows(seed=self.config.seed))
        self._iteration = 0
        self._nu_max = 2.0  # [C]'s first bound; only used with nu_max_adaptive
        self._y_sums = torch.zeros(3)  # Σ y_R, Σ y_C, count over the current iteration

    @override(TorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        module = self._module[module_id]
        for name, net, lr in ((CRITIC, module.critics, config.critic_lr), (ACTOR, module.actor, config.actor_lr)):
            params = self.get_parameters(net)
            self.register_optimizer(
                module_id=module_id, optimizer_name=name, optimizer=torch.optim.Adam(params),
                # Linear decay to lr_final_fraction·lr over the budget [C], by RLlib's Scheduler
                # (stepped after each update with the lifetime env steps).
                params=params, lr_or_lr_schedule=config.lr_or_schedule(lr),
            )

    # ----- ν (eq. 14), once per iteration before the gradient steps -----
    @override(TorchLearner)
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        """ν's step, eq. (14) (``lagrange_step``), before the iteration's gradient steps (Algorithm 2,
        line 5): Ĵ_C is the mean cost of the episodes completed in the iteration's batch (none
        completed: no step), the bound is ν_max when ``nu_max_adaptive``."""
        super().before_gradient_based_update(timesteps=timesteps)
        self._iteration = int(timesteps.get(TS_ITERATION, self._iteration))
        episode_cost = timesteps.get(TS_EPISODE_COST)
        for mid, module in self.module._rl_modules.items():
            config = self.config.get_config_for_module(mid)
            if episode_cost is not None:
                module.nu.copy_(self.lagrange_step(
                    float(module.nu), episode_cost, config.effective_cost_limit, config.nu_lr,
                    self._nu_max if config.nu_max_adaptive else None,
                ))
        self._y_sums.zero_()

    @override(TorchLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        """Steps the lr schedules, then sets [C]'s bound for the next ν step (docs/spec.md §4) from
        ȳ_R, ȳ_C, the means of y_R, y_C over every minibatch of this iteration (not the last one):

            ν_max = 2·|ȳ_R| / max(|ȳ_C|, 1e-8)        (ν_max = 2 until the first iteration ends)
        """
        super().after_gradient_based_update(timesteps=timesteps)  # steps the lr schedules
        if self._y_sums[2] == 0:
            return
        mean_r, mean_c = (self._y_sums[:2] / self._y_sums[2]).tolist()
        self._nu_max = 2.0 * abs(mean_r) / max(abs(mean_c), 1e-8)
        for mid in self.module._rl_modules:
            self.metrics.log_dict({TARGET_REWARD_MEAN: mean_r, TARGET_COST_MEAN: mean_c}, key=mid, window=1)

    @staticmethod
    def lagrange_step(nu: float, episode_cost: float, cost_limit: float, lr: float, nu_max=None) -> torch.Tensor:
        """ν's projected step, eq. (14), under [C]'s bound (docs/spec.md §4):

            ν ← min( ν_max, max(0, ν + α_ν·(Ĵ_C − b)) )

        α_ν = ``lr``, Ĵ_C = ``episode_cost``, b = ``cost_limit``; ``nu_max=None`` drops the bound,
        eq. (14) as [P] writes it."""
        nu = max(0.0, nu + lr * (episode_cost - cost_limit))
        return torch.tensor(min(nu, nu_max) if nu_max is not None else nu)

    # ----- losses -----
    @override(TorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        """The critic loss, eq. (12), and the actor loss, eqs. (15-16) (docs/spec.md §2-3):

            L_Q = Σ_j mean_B (Q_Rj(s, a) − y_R)² + Σ_j mean_B (Q_Cj(s, a) − y_C)²
            L_A = −mean_B log π_φ(ã | s*) + β·mean_B KL( π_φ(·|s*) ‖ π_φ'(·|s*) )

        y_R, y_C from :func:`critic_targets` carry no gradient (Q' ran without one). Eq. (12) writes
        ½·(y − Q)²; this is the plain squared error. s* = s' and ã = ã', the critic target's chain
        (``actor_chain_at="next"`` [C]), or s* = s with a second chain there ("current", eq. 15 as
        written): the module's forward_train chose. Returns L_Q + L_A; the two graphs are
        disjoint, so one backward serves both optimizers."""
        module = self.module[module_id].unwrapped()
        n_r = module.critics.n_reward
        q_r, q_c = reward_rows(fwd_out[M.Q_PRED], n_r), cost_rows(fwd_out[M.Q_PRED], n_r)
        y_r, y_c = critic_targets(batch, fwd_out[M.Q_TARGET_NEXT], n_r, config)
        critic_loss = ((q_r - y_r) ** 2).mean(-1).sum() + ((q_c - y_c) ** 2).mean(-1).sum()

        mean, log_std = fwd_out[M.ACTOR_MEAN], fwd_out[M.ACTOR_LOG_STD]
        nll = -gaussian_log_prob(fwd_out[M.ACTOR_TARGET_ACTION], mean, log_std).mean()
        kl = gaussian_kl(mean, log_std, fwd_out[M.TARGET_MEAN], fwd_out[M.TARGET_LOG_STD]).mean()
        actor_loss = nll + config.beta * kl

        with torch.no_grad():
            self._y_sums += torch.stack([y_r.sum(), y_c.sum(), torch.tensor(float(len(y_r)))])
            chain = fwd_out[M.CHAIN]
            self.metrics.log_dict({
                CRITIC_LOSS: critic_loss, ACTOR_LOSS: actor_loss, ACTOR_NLL: nll, ACTOR_KL: kl,
                Q_REWARD_MEAN: q_r.mean(), Q_COST_MEAN: q_c.mean(), NU: module.nu.clone(),
            }, key=module_id, window=1)
            if config.nu_max_adaptive:
                self.metrics.log_value((module_id, NU_MAX), self._nu_max, window=1)
            # Chain health over the last HEALTH_WINDOW minibatches (≈ this iteration's).
            self.metrics.log_dict({
                LANGEVIN_ENERGY_DROP: (chain.energy_start - chain.energy_end).mean(),
                LANGEVIN_DISPLACEMENT: chain.displacement.mean(),
                LANGEVIN_GRAD_NORM: chain.grad_norm,
                LANGEVIN_CLIP_FRACTION: chain.clip_fraction,
                LANGEVIN_AT_BOUND: chain.at_bound,
                ACTOR_STD_MEAN: log_std.exp().mean(),
            }, key=module_id, window=HEALTH_WINDOW)
        return critic_loss + actor_loss

    @override(TorchLearner)
    def postprocess_gradients_for_module(self, *, module_id, config, module_gradients_dict):
        grads = dict(module_gradients_dict)
        if config.actor_grad_clip:  # [C] clips the actor only (norm 40)
            actor_grads = self.filter_param_dict_for_optimizer(grads, self.get_optimizer(module_id, ACTOR))
            self._get_clip_function()(actor_grads, grad_clip=config.actor_grad_clip, grad_clip_by="global_norm")
            grads.update(actor_grads)
        return grads

    @override(TorchLearner)
    def apply_gradients(self, gradients_dict) -> None:
        """The optimizer steps (the actor's from ``actor_update_start_iteration`` on [C]), then Polyak
        of every target, θ' ← τ·θ + (1 − τ)·θ' (Algorithm 2, lines 11-13)."""
        for pid, grad in gradients_dict.items():
            self._params[pid].grad = grad
        for mid, module in self.module._rl_modules.items():
            config = self.config.get_config_for_module(mid)
            actor_on = self._iteration >= config.actor_update_start_iteration
            for name, optim in self.get_optimizers_for_module(mid):
                if name == ACTOR and not actor_on:
                    continue
                optim.step()
            if config.polyak_from_actor_start and not actor_on:
                continue  # [C]: the targets stay at their init until the actor trains
            # Algorithm 2, lines 11-13: Polyak after every gradient step.
            for main_net, target_net in module.unwrapped().get_target_network_pairs():
                update_target_network(main_net=main_net, target_net=target_net, tau=config.polyak_tau)

    # ----- state: ν rides in the module; the bound and iteration are kept here -----
    @override(TorchLearner)
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state["lac"] = {"nu_max": self._nu_max, "iteration": self._iteration, "y_sums": self._y_sums.tolist()}
        return state

    @override(TorchLearner)
    def set_state(self, state) -> None:
        super().set_state(state)
        if "lac" in state:
            self._nu_max = float(state["lac"]["nu_max"])
            self._iteration = int(state["lac"]["iteration"])
            self._y_sums = torch.tensor(state["lac"]["y_sums"])
