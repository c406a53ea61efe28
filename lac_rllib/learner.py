"""LACTorchLearner: the losses of LAC (eqs. 12-13 and 16), the ν update (eq. 14) and Polyak.

One ``learner_group.update`` call makes a whole pass of minibatches over the replay buffer
(Algorithm 2, lines 6-14); per minibatch: critic step, actor step, Polyak step of all targets
(from the first actor update on [C]). Around the pass: ν's projected step under its bound before
it (eq. 14, docs/spec.md §4), the learning-rate schedules and the next bound after it.
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

from lac_rllib import module as M
from lac_rllib.connectors import COSTS, AddCostsFromInfos, ShuffleRows
from lac_rllib.networks import gaussian_kl, gaussian_log_prob

CRITIC, ACTOR = "critic", "actor"  # optimizer names, one per loss
# Learner metric keys read elsewhere: ν and the bound ν_max it was held under this iteration;
# the iteration's mean targets (they set the next iteration's bound).
NU, NU_MAX = "nu", "nu_max"
TARGET_REWARD_MEAN, TARGET_COST_MEAN = "target_reward_mean", "target_cost_mean"
# Chain-health metrics are means over the last HEALTH_WINDOW minibatches: about one iteration
# (one pass over a full 50k buffer is 195 minibatches of 256).
HEALTH_WINDOW = 200
CHAIN_HEALTH_KEYS = ("langevin_energy_drop", "langevin_displacement", "langevin_grad_norm",
                     "langevin_clip_fraction", "langevin_at_bound", "actor_std_mean")
#: What the trainer and the sweep report per iteration from the learner's results.
REPORTED_KEYS = ("critic_loss", "actor_loss", "actor_nll", "actor_kl", "q_reward_mean", "q_cost_mean",
                 TARGET_REWARD_MEAN, TARGET_COST_MEAN, NU_MAX, *CHAIN_HEALTH_KEYS)
# Keys the algorithm passes in ``timesteps`` to every update call.
TS_EPISODE_COST, TS_ITERATION = "lac_episode_cost", "lac_training_iteration"


def critic_targets(batch, q_next: torch.Tensor, n_reward: int, config) -> tuple[torch.Tensor, torch.Tensor]:
    """eq. (13) with clipped double-Q: y_R uses the min over the reward targets, y_C the max
    over the cost targets. ``terminated`` cuts the bootstrap; time-limit truncation does not
    (docs/spec.md §2 [D]) unless ``bootstrap_on_truncation`` is off, which reproduces [C]."""
    done = batch[Columns.TERMINATEDS].float()
    if not config.bootstrap_on_truncation:
        done = torch.maximum(done, batch[Columns.TRUNCATEDS].float())
    y_r = config.reward_scale * batch[Columns.REWARDS] + config.gamma * (1 - done) * q_next[:n_reward].min(0).values
    y_c = batch[COSTS] + config.cost_gamma * (1 - done) * q_next[n_reward:].max(0).values
    return y_r, y_c


class LACTorchLearner(TorchLearner):
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
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
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

    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().after_gradient_based_update(timesteps=timesteps)  # steps the lr schedules
        if self._y_sums[2] == 0:
            return
        # The iteration's mean targets (every minibatch, not the last one) and, from them, [C]'s
        # ν bound for the next iteration: ν_max = 2·|mean y_R| / |mean y_C| (docs/spec.md §4).
        mean_r, mean_c = (self._y_sums[:2] / self._y_sums[2]).tolist()
        self._nu_max = 2.0 * abs(mean_r) / max(abs(mean_c), 1e-8)
        for mid in self.module._rl_modules:
            self.metrics.log_dict({TARGET_REWARD_MEAN: mean_r, TARGET_COST_MEAN: mean_c}, key=mid, window=1)

    @staticmethod
    def lagrange_step(nu: float, episode_cost: float, cost_limit: float, lr: float, nu_max=None) -> torch.Tensor:
        """eq. (14): ν ← max(0, ν + α_ν·(Ĵ_C − b)), optionally capped at ν_max [C]."""
        nu = max(0.0, nu + lr * (episode_cost - cost_limit))
        return torch.tensor(min(nu, nu_max) if nu_max is not None else nu)

    # ----- losses -----
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        module = self.module[module_id].unwrapped()
        n_r = module.critics.n_reward
        q = fwd_out[M.Q_PRED]
        y_r, y_c = critic_targets(batch, fwd_out[M.Q_TARGET_NEXT], n_r, config)
        # eq. (12), summed over the twin critics of each kind.
        critic_loss = ((q[:n_r] - y_r) ** 2).mean(-1).sum() + ((q[n_r:] - y_c) ** 2).mean(-1).sum()

        # eq. (16): maximum likelihood of the Langevin action plus β·KL(π_φ ‖ π_φ').
        mean, log_std = fwd_out[M.ACTOR_MEAN], fwd_out[M.ACTOR_LOG_STD]
        nll = -gaussian_log_prob(fwd_out[M.ACTOR_TARGET_ACTION], mean, log_std).mean()
        kl = gaussian_kl(mean, log_std, fwd_out[M.TARGET_MEAN], fwd_out[M.TARGET_LOG_STD]).mean()
        actor_loss = nll + config.beta * kl

        with torch.no_grad():
            self._y_sums += torch.stack([y_r.sum(), y_c.sum(), torch.tensor(float(len(y_r)))])
            chain = fwd_out[M.CHAIN]
            self.metrics.log_dict({
                "critic_loss": critic_loss, "actor_loss": actor_loss, "actor_nll": nll, "actor_kl": kl,
                "q_reward_mean": q[:n_r].mean(), "q_cost_mean": q[n_r:].mean(),
                NU: module.nu.clone(),
            }, key=module_id, window=1)
            if config.nu_max_adaptive:
                self.metrics.log_value((module_id, NU_MAX), self._nu_max, window=1)
            # Chain health over the last HEALTH_WINDOW minibatches (≈ this iteration's).
            health = ((chain.energy_start - chain.energy_end).mean(), chain.displacement.mean(),
                      chain.grad_norm, chain.clip_fraction, chain.at_bound, log_std.exp().mean())
            self.metrics.log_dict(dict(zip(CHAIN_HEALTH_KEYS, health)), key=module_id, window=HEALTH_WINDOW)
        return critic_loss + actor_loss  # disjoint graphs: one backward serves both optimizers

    def postprocess_gradients_for_module(self, *, module_id, config, module_gradients_dict):
        grads = dict(module_gradients_dict)
        if config.actor_grad_clip:  # [C] clips the actor only (norm 40)
            actor_grads = self.filter_param_dict_for_optimizer(grads, self.get_optimizer(module_id, ACTOR))
            self._get_clip_function()(actor_grads, grad_clip=config.actor_grad_clip, grad_clip_by="global_norm")
            grads.update(actor_grads)
        return grads

    def apply_gradients(self, gradients_dict) -> None:
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
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state["lac"] = {"nu_max": self._nu_max, "iteration": self._iteration, "y_sums": self._y_sums.tolist()}
        return state

    def set_state(self, state) -> None:
        super().set_state(state)
        if "lac" in state:
            self._nu_max = float(state["lac"]["nu_max"])
            self._iteration = int(state["lac"]["iteration"])
            self._y_sums = torch.tensor(state["lac"]["y_sums"])
