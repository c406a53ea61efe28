"""SACLagTorchLearner: OmniSafe's SACLag update (``sac_lag.py`` on ``sac.py``/``ddpg.py``) inside
RLlib's Learner hooks.

One ``learner_group.update`` call makes all the gradient steps of an iteration (one per env step,
``updates_per_env_step``); per minibatch, in OmniSafe's order:

1. the reward and cost critic steps (``compute_loss_for_module``: the targets in
   :func:`critic_targets`, the losses beside them; RLlib's backward and ``apply_gradients``);
2. on every ``policy_delay``-th step only, the actor step on the critics *after* their step, as
   OmniSafe's ``ddpg.py`` ``_update`` orders them, and then Polyak of both target critics
   (``apply_gradients``: the actor's own forward and backward on the minibatch's observations; on
   the other steps its Adam is not stepped at all);
3. once past ``warmup_env_steps``, one step of λ (a LagrangeMultiplier with OmniSafe's Adam rule)
   from Ĵ_C, the mean cost of the last ``cost_window`` completed episodes. Ĵ_C is fixed within a
   call (the episodes arrive between calls), so N λ steps per call are OmniSafe's one per env step.

Each critic network and the actor are clipped to a global gradient norm of ``max_grad_norm``
(``postprocess_gradients_for_module``, one clip per optimizer, as OmniSafe clips per network), and
the targets averaged, through constrained/gradients.py (RLlib's clip and Polyak formulas, in
foreach ops). With ``update_path="fused"`` the call's minibatches run inside one ``_update``
(constrained/minibatch_loop.py): the same steps, bit for bit, without RLlib's per-minibatch work.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.algorithms.sac_lag import module as M
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.cpus import learner_torch
from lac_rllib.constrained.gradients import clip_global_norm_, clip_global_norms_, polyak_, zero_non_finite_
from lac_rllib.constrained.lagrange import (
    AdamStep,
    GradientStep,
    LagrangeMultiplier,
    Multipliers,
    fixed_multiplier,
    multipliers_for,
    nu_total,
    nu_weighted,
    restore_multipliers,
)
from lac_rllib.constrained.metrics import (
    ACTOR_LOSS,
    COST_WINDOW_MEAN,
    CRITIC_LOSS,
    NU,
    Q_COST_MEAN,
    Q_REWARD_MEAN,
    TS_CONSTRAINT_COSTS,
    TS_EPISODE_COSTS,
    per_constraint,
)
from lac_rllib.constrained.minibatch_loop import FusedMinibatchLoop

REWARD_CRITIC, COST_CRITIC, ACTOR = "reward_critic", "cost_critic", "actor"  # optimizer names
LAGRANGE_RULES = {"adam": AdamStep, "gradient": GradientStep}
#: The learner's own entry in its checkpointed state (RLlib's keeps only the module, the optimizers
#: and the metrics): the update count, the cost window and each multiplier's rule state.
STATE_SAC_LAG = "sac_lag"


def critic_targets(batch: dict, fwd_out: dict, config) -> tuple[torch.Tensor, torch.Tensor]:
    """OmniSafe's targets (sac.py ``_update_reward_critic``, ddpg.py ``_update_cost_critic``):

        y_R = r + γ·(1 − d)·( min_j Q'_Rj(s', a') − α·log π(a'|s') ),   a' ~ π(·|s')
        y_C = c + γ_C·(1 − d)·Q'_C(s', squash(μ(s')))

    d = terminated: time-limit truncation bootstraps, as OmniSafe stores done = terminated ∧ ¬truncated.
    The inputs come from the module's forward without gradient, so neither target carries one.
    1 − d in the critics' dtype (float32 in a run, as before: the same bits), so that γ·(1 − d) is
    not rounded to float32 in a float64 step (tests/algorithms/sac_lag/test_sac_lag_golden.py)."""
    not_done = 1.0 - batch[Columns.TERMINATEDS].to(fwd_out[M.Q_COST_NEXT].dtype)
    soft_next = fwd_out[M.Q_REWARD_NEXT].min(0).values - config.alpha * fwd_out[M.LOGP_NEXT]
    y_r = batch[Columns.REWARDS] + config.gamma * not_done * soft_next
    if batch[COSTS].dim() == 2:  # K constraints: y_Ck from each constraint's cost critic, (B, K)
        not_done = not_done[:, None]
    y_c = batch[COSTS] + config.cost_gamma * not_done * fwd_out[M.Q_COST_NEXT]
    return y_r, y_c


def actor_loss(actor_out: dict, nu: torch.Tensor, alpha: float) -> torch.Tensor:
    """OmniSafe's sac_lag.py ``_loss_pi``, at ã ~ π(·|s) reparameterised:

        L_π = mean_B( α·log π(ã|s) − min_j Q_Rj(s, ã) + λ·Q_C(s, ã) ) / (1 + λ)

    λ is a constant here (the multiplier's value, no gradient), in the critics' dtype: OmniSafe adds
    ``1 + λ.item()`` in Python floats, so in a float64 step 1 + λ is not rounded to float32. With K
    constraints Σ_k λ_k·Q_Ck(s, ã) and 1 + Σ_k λ_k."""
    nu = nu.detach().to(actor_out[M.Q_COST_PI].dtype)
    per_sample = (alpha * actor_out[M.LOGP] - actor_out[M.Q_REWARD_PI].min(0).values
                  + nu_weighted(nu, actor_out[M.Q_COST_PI]))
    return per_sample.mean() / (1.0 + nu_total(nu))


class SACLagTorchLearner(FusedMinibatchLoop, TorchLearner):
    MINIBATCH_COLUMNS = (Columns.OBS, Columns.ACTIONS, Columns.NEXT_OBS, Columns.REWARDS, Columns.TERMINATEDS, COSTS)

    @override(TorchLearner)
    def build(self) -> None:
        # threads; no NaN fill of fresh tensors; denormals flushed if asked (constrained/cpus.py)
        learner_torch(self.config.torch_threads, flush_denormal=self.config.flush_denormal)
        super().build()  # the learner connector comes from SACLagConfig.build_learner_connector
        self.module.foreach_module(
            lambda mid, mod: mod.make_target_networks() if isinstance(mod, TargetNetworkAPI) else None)
        self.updates = 0  # gradient steps so far: decides the policy-delay steps
        self.cost_window: deque = deque(maxlen=self.config.cost_window)  # K-lists with K constraints
        #: The names of K > 1 constraints (None: one), whose costs the window holds per episode.
        self.constraint_names = getattr(self.config.several_constraints, "names", None)
        self.multipliers = {mid: self.make_multiplier(mid, module) for mid, module in self.module.items()}
        self._cost_this_call: float | None = None  # Ĵ_C of the current update call; None: no λ step
        self._last: dict[str, dict[str, torch.Tensor]] = {}  # the last minibatch's metrics per module
        self._actor_obs: dict[str, torch.Tensor] = {}  # the minibatch's observations, for the actor's step

    def make_multiplier(self, module_id, module) -> LagrangeMultiplier | Multipliers:
        """λ of ``module``: OmniSafe's Adam step on −λ·(Ĵ_C − b), then λ ≥ 0 (no upper bound [O]); or
        held at ``nu_fixed`` for the whole run. With K constraints a λ_k each."""
        config = self.config.get_config_for_module(module_id)
        if held := fixed_multiplier(module.unwrapped().nu, config):
            return held
        return multipliers_for(module.unwrapped().nu, config, lambda value, b: LagrangeMultiplier(
            value, cost_limit=b, rule=LAGRANGE_RULES[config.lagrangian_rule](config.lagrangian_lr), bounded=False))

    @override(TorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        """One Adam per network [O], fused: torch's one-kernel Adam, the same update to float
        rounding and ~3x faster than the per-tensor loop on these small tensors."""
        module = self.module[module_id]
        for name, net, lr in ((REWARD_CRITIC, module.reward_critics, config.critic_lr),
                              (COST_CRITIC, module.cost_critic, config.critic_lr),
                              (ACTOR, module.actor, config.actor_lr)):
            params = self.get_parameters(net)
            self.register_optimizer(module_id=module_id, optimizer_name=name, params=params, lr_or_lr_schedule=lr,
                                    optimizer=torch.optim.Adam(params, fused=True))

    def is_actor_step(self) -> bool:
        """Whether the coming gradient step is a policy-delay step: OmniSafe counts updates from 1
        and steps the actor when the count is a multiple of ``policy_delay``."""
        return (self.updates + 1) % self.config.policy_delay == 0

    @property
    def episode_cost(self) -> float | list[float] | None:
        """Ĵ_C: the mean cost of the last ``cost_window`` completed episodes (None before the first);
        K means with K constraints."""
        if not self.cost_window:
            return None
        return np.mean(self.cost_window, axis=0).tolist() if self.constraint_names else float(np.mean(self.cost_window))

    # ----- around the gradient steps of one update call -----
    @override(TorchLearner)
    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)
        if self.constraint_names:
            self.cost_window.extend(list(map(float, c)) for c in timesteps.get(TS_CONSTRAINT_COSTS, ()))
        else:
            self.cost_window.extend(float(c) for c in timesteps.get(TS_EPISODE_COSTS, ()))
        # OmniSafe: λ steps only after warmup_epochs; here after warmup_env_steps sampled.
        past_warmup = timesteps.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0) > self.config.warmup_env_steps
        self._cost_this_call = self.episode_cost if past_warmup else None

    @override(TorchLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().after_gradient_based_update(timesteps=timesteps)
        # Logged once per call (the last minibatch's values), not per minibatch: RLlib's logging
        # costs more than a tiny network's gradient step.
        names, j_c = self.constraint_names, self._cost_this_call
        for mid, module in self.module.items():
            nu = module.unwrapped().nu
            if names:  # each λ_k and Ĵ_Ck; ν itself reports the largest
                own = {NU: nu.max(), **{per_constraint(NU, n): nu[k].clone() for k, n in enumerate(names)},
                       **{per_constraint(COST_WINDOW_MEAN, n): float("nan") if j_c is None else j_c[k]
                          for k, n in enumerate(names)}}
            else:
                own = {NU: nu.clone(), COST_WINDOW_MEAN: float("nan") if j_c is None else j_c}
            self.metrics.log_dict({**self._last.get(mid, {}), **own}, key=mid, window=1)

    # ----- losses -----
    @override(TorchLearner)
    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out) -> torch.Tensor:
        """The critic losses: MSE to the targets, summed over the two reward critics [O]. The
        actor's loss waits for the critics' step (:meth:`apply_gradients`); the minibatch's
        observations are kept for it."""
        y_r, y_c = critic_targets(batch, fwd_out, config)
        q_r, q_c = fwd_out[M.Q_REWARD], fwd_out[M.Q_COST]
        reward_loss = ((q_r - y_r) ** 2).mean(-1).sum()  # mse(Q_R1, y_R) + mse(Q_R2, y_R)
        # K constraints: each cost critic's MSE, summed
        cost_loss = ((q_c - y_c) ** 2).mean() if q_c.dim() == 1 else ((q_c - y_c) ** 2).mean(0).sum()
        self._last[module_id] = {**self._last.get(module_id, {}),
                                 CRITIC_LOSS: reward_loss.detach() + cost_loss.detach(),
                                 Q_REWARD_MEAN: q_r.detach().mean(), Q_COST_MEAN: q_c.detach().mean()}
        self._actor_obs[module_id] = batch[Columns.OBS]
        return reward_loss + cost_loss

    @override(TorchLearner)
    def postprocess_gradients_for_module(self, *, module_id, config, module_gradients_dict):
        """Drops the gradients that are None (the actor's: its step comes after the critics'),
        then clips each network's gradients to a global norm of ``max_grad_norm`` [O]."""
        grads = {ref: g for ref, g in module_gradients_dict.items() if g is not None}
        if config.max_grad_norm is not None:
            clip_global_norms_([list(self.filter_param_dict_for_optimizer(grads, optimizer).values())
                                for _, optimizer in self.get_optimizers_for_module(module_id)], config.max_grad_norm)
        return grads

    @override(TorchLearner)
    def apply_gradients(self, gradients_dict) -> None:
        """The critics' steps through TorchLearner's (its NaN/inf guard included: a parameter whose
        .grad is None, the actor's, is skipped by Adam, moments and step count included). Then, on a
        policy-delay step, the actor's step on the stepped critics and Polyak θ' ← τ·θ + (1 − τ)·θ'
        of both target critics [O ddpg.py ``_update``]; then λ's step."""
        actor_step = self.is_actor_step()
        zero_non_finite_(gradients_dict)  # RLlib's NaN/inf guard, one test for all (constrained/gradients.py)
        super().apply_gradients(gradients_dict)
        for mid, module in self.module.items():
            config = self.config.get_config_for_module(mid)
            obs = self._actor_obs.pop(mid, None)
            if actor_step and obs is not None:
                self._actor_step(mid, module.unwrapped(), obs, config)
                polyak_(module.unwrapped().get_target_network_pairs(), config.polyak_tau)
            self.multipliers[mid].step(self._cost_this_call)  # None (warm-up, no episode yet): no step
        self.updates += 1

    def _actor_step(self, module_id, module, obs: torch.Tensor, config) -> None:
        """One step of the actor on :func:`actor_loss` at ``obs``, the critics as their step left
        them [O ddpg.py: ``_update_actor`` after ``_update_reward_critic`` and ``_update_cost_critic``]:
        its gradient clipped to ``max_grad_norm`` [O], RLlib's NaN/inf guard, then TorchLearner's
        optimizer steps, the critics' gradients cleared first so that only the actor's Adam steps."""
        for _, optimizer in self.get_optimizers_for_module(module_id):
            optimizer.zero_grad(set_to_none=True)
        params = self.get_parameters(module.actor)
        pi_loss = actor_loss(module.forward_actor(obs), module.nu, config.alpha)
        grads = dict(zip((self.get_param_ref(p) for p in params), torch.autograd.grad(pi_loss, params)))
        if config.max_grad_norm is not None:
            clip_global_norm_(list(grads.values()), config.max_grad_norm)
        zero_non_finite_(grads)
        super().apply_gradients(grads)
        self._last[module_id][ACTOR_LOSS] = pi_loss.detach()

    # ----- state: λ rides in the module; the count, the window and the rules' state here -----
    @override(TorchLearner)
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[STATE_SAC_LAG] = {
            "updates": self.updates, "cost_window": list(self.cost_window),  # K-lists with K constraints
            "lagrange": {mid: m.get_state() for mid, m in self.multipliers.items()},
        }
        return state

    @override(TorchLearner)
    def set_state(self, state) -> None:
        super().set_state(state)
        own = state.get(STATE_SAC_LAG)
        restore_multipliers(self.multipliers, self.module, own["lagrange"] if own is not None else {})
        if own is not None:
            self.updates = int(own["updates"])
            self.cost_window.clear()
            self.cost_window.extend(list(map(float, c)) if self.constraint_names else float(c)
                                    for c in own["cost_window"])

