"""LACTorchLearner: the losses of LAC (eqs. 12-13, 15-16), the ν update (eq. 14) and Polyak.

One ``learner_group.update`` call makes a whole pass of minibatches over the replay buffer
(Algorithm 2, lines 6-14); per minibatch: critic step, actor step, Polyak step of all targets
(from the first actor update on [C]). Around the pass: ν's projected step under its bound before
it (eq. 14, docs/spec.md §4), the learning-rate schedules and the next bound after it.

Each equation is written out, in the notation of docs/spec.md, where it is computed: the critic
targets (13) in :func:`critic_targets`; the critic loss (12) and the actor loss (15-16) in
``compute_loss_for_module``; ν's step (14) and its bound ν_max in each module's
:class:`~lac_rllib.constrained.lagrange.LagrangeMultiplier` (``self.multipliers``); Polyak in
``apply_gradients``. Methods marked ``@override`` are RLlib's hooks; the others are LAC's own.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.lac import module as M
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.cpus import learner_torch
from lac_rllib.constrained.gradients import clip_global_norm_, polyak_, zero_non_finite_
from lac_rllib.constrained.lagrange import (
    GradientStep,
    LagrangeMultiplier,
    Multipliers,
    each_multiplier,
    fixed_multiplier,
    multipliers_for,
    restore_multipliers,
)
from lac_rllib.constrained.metrics import (
    ACTOR_KL,
    ACTOR_LOSS,
    ACTOR_NLL,
    ACTOR_STD_MEAN,
    CRITIC_LOSS,
    LANGEVIN_AT_BOUND,
    LANGEVIN_CLIP_FRACTION,
    LANGEVIN_DISPLACEMENT,
    LANGEVIN_ENERGY_DROP,
    LANGEVIN_GRAD_NORM,
    NU,
    NU_MAX,
    Q_COST_MEAN,
    Q_REWARD_MEAN,
    TARGET_COST_MEAN,
    TARGET_REWARD_MEAN,
    TS_ITERATION,
    TS_MEAN_EPISODE_COST,
    per_constraint,
)
from lac_rllib.constrained.networks import cost_rows, gaussian_kl, gaussian_log_prob, max_per_constraint, reward_rows

CRITIC, ACTOR = "critic", "actor"  # optimizer names, one per loss
# Chain health is averaged over the last HEALTH_WINDOW minibatches, about one iteration (one pass
# over a full 50k buffer is 195 minibatches of 256).
HEALTH_WINDOW = 200
#: The learner's own entries in its checkpointed state (RLlib's get_state keeps only the module,
#: the optimizers and the metrics: docs/dependencies.md).
STATE_ITERATION, STATE_LAGRANGE = "lac_iteration", "lagrange"


def critic_targets(batch, q_next: torch.Tensor, n_reward: int, config) -> tuple[torch.Tensor, torch.Tensor]:
    """The critic targets, eq. (13) with clipped double-Q (docs/spec.md §2):

        y_R = k_r·r + γ·(1 − d)·min_j Q'_Rj(s', ã')
        y_C =     c + γ_C·(1 − d)·max_j Q'_Cj(s', ã')

    ``q_next`` is the target ensemble Q' at (s', ã') (E, B); k_r = ``reward_scale``, γ_C =
    ``cost_gamma``. d = terminated: time-limit truncation bootstraps [D] unless
    ``bootstrap_on_truncation`` is off, d = terminated ∨ truncated, which reproduces [C]. With K
    constraints (costs (B, K)) y_C is (B, K), each from its own twin cost critics."""
    # d in the critics' dtype: float32 as before in training; in a float64 step (the golden test)
    # a float32 d would round γ·(1 − d) to float32.
    done = batch[Columns.TERMINATEDS].to(q_next.dtype)
    if not config.bootstrap_on_truncation:
        done = torch.maximum(done, batch[Columns.TRUNCATEDS].to(q_next.dtype))
    min_q_r = reward_rows(q_next, n_reward).min(0).values
    y_r = config.reward_scale * batch[Columns.REWARDS] + config.gamma * (1 - done) * min_q_r
    costs = batch[COSTS]
    if costs.dim() == 1:
        max_q_c = cost_rows(q_next, n_reward).max(0).values
        return y_r, costs + config.cost_gamma * (1 - done) * max_q_c
    # K constraints: y_Ck = c_k + γ_C·(1 − d)·max_j Q'_Ckj, (B, K)
    max_q_c = max_per_constraint(cost_rows(q_next, n_reward), costs.shape[1]).T
    return y_r, costs + config.cost_gamma * (1 - done)[:, None] * max_q_c


class LACTorchLearner(TorchLearner):
    @override(TorchLearner)
    def build(self) -> None:
        learner_torch(self.config.torch_threads)  # threads; no NaN fill of fresh tensors (constrained/cpus.py)
        super().build()  # the learner connector comes from LACConfig.build_learner_connector
        self.module.foreach_module(
            lambda mid, mod: mod.make_target_networks() if isinstance(mod, TargetNetworkAPI) else None
        )
        self._iteration = 0
        self.multipliers = {mid: self.make_multiplier(mid, module) for mid, module in self.module.items()}
        #: Each module's constraint names where it holds several apart (None: one), read once here.
        self.constraint_names = {mid: getattr(self.config.get_config_for_module(mid).several_constraints, "names", None)
                                 for mid in self.module.keys()}

    def make_multiplier(self, module_id, module) -> LagrangeMultiplier | Multipliers:
        """ν of ``module``: eq. (14)'s gradient step, under [C]'s bound when ``nu_max_adaptive``; or
        held at ``nu_fixed`` for the whole run. With K constraints a ν_k each, each bound from ȳ_R
        and its own ȳ_Ck."""
        config = self.config.get_config_for_module(module_id)
        if held := fixed_multiplier(module.unwrapped().nu, config):
            return held
        return multipliers_for(module.unwrapped().nu, config, lambda value, b: LagrangeMultiplier(
            value, cost_limit=b, rule=GradientStep(config.nu_lr), bounded=config.nu_max_adaptive))

    @override(TorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        module = self.module[module_id]
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
        """ν's step, eq. (14), before the iteration's gradient steps (Algorithm 2, line 5): Ĵ_C is
        the mean cost of the episodes completed in the iteration's batch (none completed: no step)."""
        super().before_gradient_based_update(timesteps=timesteps)
        self._iteration = int(timesteps.get(TS_ITERATION, self._iteration))
        for multiplier in self.multipliers.values():
            multiplier.step(timesteps.get(TS_MEAN_EPISODE_COST))  # K values with K constraints
            for part in each_multiplier(multiplier):
                part.bound.start_iteration()

    @override(TorchLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        """Steps the lr schedules, then sets each multiplier's bound for the next ν step from this
        iteration's mean targets ȳ_R, ȳ_C (logged)."""
        super().after_gradient_based_update(timesteps=timesteps)  # steps the lr schedules
        for mid, multiplier in self.multipliers.items():
            names = self.constraint_names[mid]
            for k, part in enumerate(each_multiplier(multiplier)):
                means = part.bound.end_iteration()
                if means is not None:
                    self.metrics.log_dict({TARGET_REWARD_MEAN: means[0],
                                           self.key(TARGET_COST_MEAN, names, k): means[1]}, key=mid, window=1)

    @staticmethod
    def key(key: str, names, k: int) -> str:
        return key if names is None else per_constraint(key, names[k])

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
        if y_c.dim() == 2:  # K constraints: each twin pair regresses on its own y_Ck
            y_c = y_c.T.repeat_interleave(q_c.shape[0] // y_c.shape[1], dim=0)
        critic_loss = ((q_r - y_r) ** 2).mean(-1).sum() + ((q_c - y_c) ** 2).mean(-1).sum()

        mean, log_std = fwd_out[M.ACTOR_MEAN], fwd_out[M.ACTOR_LOG_STD]
        nll = -gaussian_log_prob(fwd_out[M.ACTOR_TARGET_ACTION], mean, log_std).mean()
        kl = gaussian_kl(mean, log_std, fwd_out[M.TARGET_MEAN], fwd_out[M.TARGET_LOG_STD]).mean()
        actor_loss = nll + config.beta * kl

        with torch.no_grad():
            multiplier, names = self.multipliers[module_id], self.constraint_names[module_id]
            parts = each_multiplier(multiplier)
            for k, part in enumerate(parts):  # y_C (B,), or its rows of constraint k's twin critics
                part.bound.observe(y_r, y_c if names is None else y_c[k * (len(y_c) // len(parts))])
            chain = fwd_out[M.CHAIN]
            self.metrics.log_dict({
                CRITIC_LOSS: critic_loss, ACTOR_LOSS: actor_loss, ACTOR_NLL: nll, ACTOR_KL: kl,
                Q_REWARD_MEAN: q_r.mean(), Q_COST_MEAN: q_c.mean(),
                NU: module.nu.clone() if names is None else module.nu.max(),
                **({} if names is None else {per_constraint(NU, n): module.nu[k].clone() for k, n in enumerate(names)}),
            }, key=module_id, window=1)
            for k, part in enumerate(parts):
                if part.upper is not None:
                    self.metrics.log_value((module_id, self.key(NU_MAX, names, k)), part.upper, window=1)
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
            clip_global_norm_(list(actor_grads.values()), config.actor_grad_clip)  # RLlib's clip's arithmetic
            grads.update(actor_grads)
        return grads

    @override(TorchLearner)
    def apply_gradients(self, gradients_dict) -> None:
        """TorchLearner's optimizer steps (with its NaN/inf gradient guard), the actor's only from
        ``actor_update_start_iteration`` on [C]; then Polyak of every target,
        θ' ← τ·θ + (1 − τ)·θ' (Algorithm 2, lines 11-13)."""
        grads = dict(gradients_dict)
        zero_non_finite_(grads)  # RLlib's NaN/inf guard, one test for all (constrained/gradients.py)
        frozen_actors = []
        for mid in self.module.keys():
            config = self.config.get_config_for_module(mid)
            if self._iteration < config.actor_update_start_iteration:
                actor = self.get_optimizer(mid, ACTOR)
                for pid in self.filter_param_dict_for_optimizer(grads, actor):
                    del grads[pid]
                frozen_actors.append(actor)
        # A parameter whose .grad is None is skipped by Adam (no step, no moment update), so the
        # actor's optimizer state stays as if it had not been stepped at all, as [C]'s.
        for optim in frozen_actors:
            optim.zero_grad(set_to_none=True)
        super().apply_gradients(grads)
        for mid, module in self.module.items():
            config = self.config.get_config_for_module(mid)
            if config.polyak_from_actor_start and self._iteration < config.actor_update_start_iteration:
                continue  # [C]: the targets stay at their init until the actor trains
            # Algorithm 2, lines 11-13: Polyak after every gradient step (RLlib's formula and rounding).
            polyak_(module.unwrapped().get_target_network_pairs(), config.polyak_tau)

    # ----- state: ν rides in the module; the iteration and each multiplier's rule and bound here -----
    @override(TorchLearner)
    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[STATE_ITERATION] = self._iteration
        state[STATE_LAGRANGE] = {mid: m.get_state() for mid, m in self.multipliers.items()}
        return state

    @override(TorchLearner)
    def set_state(self, state) -> None:
        super().set_state(state)
        restore_multipliers(self.multipliers, self.module, state.get(STATE_LAGRANGE, {}))
        self._iteration = int(state.get(STATE_ITERATION, self._iteration))
