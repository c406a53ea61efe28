"""LACTorchLearner: the losses of LAC (eqs. 12-13 and 16), the ν update (eq. 14) and Polyak.

One ``learner_group.update`` call makes a whole pass of minibatches over the replay buffer
(Algorithm 2, lines 6-14); per minibatch: critic step, actor step, Polyak step of all targets.
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
# Keys the algorithm passes in ``timesteps`` to every update call.
TS_EPISODE_COST, TS_ITERATION = "lac_episode_cost", "lac_training_iteration"


def critic_targets(batch, q_next: torch.Tensor, n_reward: int, config) -> tuple[torch.Tensor, torch.Tensor]:
    """eq. (13) with clipped double-Q: y_R uses the min over the reward targets, y_C the max
    over the cost targets. ``terminated`` cuts the bootstrap; time-limit truncation does not
    (SPEC §2 [D]) unless ``bootstrap_on_truncation`` is off, which reproduces [C]."""
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
        # s' for the critic targets, then the cost of each row (NOTES.md: this order).
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
                params=params, lr_or_lr_schedule=lr,
            )

    # ----- ν (eq. 14), once per iteration before the gradient steps -----
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)
        self._iteration = int(timesteps.get(TS_ITERATION, self._iteration))
        episode_cost = timesteps.get(TS_EPISODE_COST)
        for mid, module in self.module._rl_modules.items():
            config = self.config.get_config_for_module(mid)
            if config.nu_max_adaptive and self._y_sums[2] > 0:
                mean_r, mean_c = (self._y_sums[:2] / self._y_sums[2]).tolist()
                self._nu_max = 2.0 * abs(mean_r) / max(abs(mean_c), 1e-8)
            if episode_cost is not None:
                module.nu.copy_(self.lagrange_step(
                    float(module.nu), episode_cost, config.effective_cost_limit, config.nu_lr,
                    self._nu_max if config.nu_max_adaptive else None,
                ))
        self._y_sums.zero_()

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
                "target_reward_mean": y_r.mean(), "target_cost_mean": y_c.mean(),
                "langevin_energy_drop": (chain.energy_start - chain.energy_end).mean(),
                "langevin_displacement": chain.displacement.mean(),
                "actor_std_mean": log_std.exp().mean(),
                "nu": module.nu.clone(), "nu_max": torch.tensor(self._nu_max),
            }, key=module_id, window=1)
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
            for name, optim in self.get_optimizers_for_module(mid):
                if name == ACTOR and self._iteration < config.actor_update_start_iteration:
                    continue
                optim.step()
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
