"""SACLagTorchRLModule: SAC-Lag's networks and their forward passes (the losses live in the Learner).

- ``actor``: the tanh-Gaussian π(a|s) (networks.SquashedGaussianActor); the env runners sample it
  through ``action_dist_cls`` (RLlib's TorchSquashedGaussian on the action bounds).
- ``reward_critics``: Q_R1, Q_R2 as one batched ensemble; ``cost_critic``: the one Q_C [O]. Two
  ensembles, not one, so each has its own optimizer and gradient clip, as OmniSafe's two critics do.
- ``target_reward_critics`` / ``target_cost_critic``: their Polyak copies. There is no target
  actor: OmniSafe's SAC targets use the online actor.
- ``nu``: the Lagrange multiplier λ, a buffer so it travels with the weights (checkpoints, env
  runners); the Learner's LagrangeMultiplier is its only writer.

Only the actor and ν exist on env runners: critics and targets are non-inference attributes.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.sac_lag.config import critic_matmul_dtype
from lac_rllib.algorithms.sac_lag.networks import SquashedGaussianActor, squash, squashed_gaussian, squashed_log_prob
from lac_rllib.constrained.lagrange import initial_nus
from lac_rllib.constrained.networks import CriticEnsemble
from lac_rllib.constrained.precision import TORCH_DTYPES
from lac_rllib.families.off_policy.module import ActorCriticRLModule

# Keys of the forward outputs, declared once.
Q_REWARD = "q_reward"  # (2, B) Q_R1, Q_R2 at (s, a)
Q_COST = "q_cost"  # (B,) Q_C at (s, a); each Q_C below is (B, K) with K constraints
Q_REWARD_NEXT = "q_reward_next"  # (2, B) target Q'_R at (s', a'), a' ~ π(·|s')
LOGP_NEXT = "logp_next"  # (B,) log π(a'|s')
Q_COST_NEXT = "q_cost_next"  # (B,) target Q'_C at (s', squash(μ(s')))
LOGP = "logp"  # (B,) log π(ã|s), ã the reparameterised sample at s
Q_REWARD_PI = "q_reward_pi"  # (2, B) Q_R at (s, ã), critics' weights frozen
Q_COST_PI = "q_cost_pi"  # (B,) Q_C at (s, ã), critic's weights frozen


class SACLagTorchRLModule(ActorCriticRLModule):
    TARGETS = {"reward_critics": "target_reward_critics", "cost_critic": "target_cost_critic"}

    @override(TorchRLModule)
    def setup(self):
        cfg = self.model_config
        obs_dim, act_dim = int(self.observation_space.shape[0]), int(self.action_space.shape[0])
        self.actor = SquashedGaussianActor(obs_dim, act_dim, hidden=tuple(cfg["actor_hidden"]),
                                           activation=cfg["activation"], log_std_min=cfg["log_std_min"],
                                           log_std_max=cfg["log_std_max"])
        # K constraints: λ (K,) and a cost critic each (one ensemble of K members).
        self.num_constraints = k = int(cfg.get("num_constraints", 1))
        self.register_buffer("nu", initial_nus(cfg, k))
        # The action bounds as buffers: they move with the module to its device, and a restored
        # module's state is complete (lac_rllib.evaluation checks every buffer is restored).
        self.register_buffer("action_low", torch.tensor(np.array(self.action_space.low), dtype=torch.float32))
        self.register_buffer("action_high", torch.tensor(np.array(self.action_space.high), dtype=torch.float32))
        self.action_dist_cls = squashed_gaussian(self.action_low, self.action_high)
        if not self.inference_only:
            hidden, activation = tuple(cfg["critic_hidden"]), cfg["activation"]
            # The critics' hidden matmuls in critic_dtype ("auto" resolved here, on the learner's CPU).
            dtype = TORCH_DTYPES[critic_matmul_dtype(cfg.get("critic_dtype", "float32"), hidden)]
            self.reward_critics = CriticEnsemble(obs_dim, act_dim, hidden=hidden, n_reward=2, n_cost=0,
                                                 activation=activation, matmul_dtype=dtype)
            # CriticEnsemble counts its members as n_reward + n_cost; the split matters only to
            # LAC's chain, so the cost critic is a one-member ensemble (K members with K constraints).
            self.cost_critic = CriticEnsemble(obs_dim, act_dim, hidden=hidden, n_reward=k, n_cost=0,
                                              activation=activation, matmul_dtype=dtype)

    def cost_values(self, q: torch.Tensor) -> torch.Tensor:
        """Q_C from the cost ensemble's output (K, B): (B,) with one constraint, (B, K) with K."""
        return q[0] if self.num_constraints == 1 else q.T

    # ----- acting (env runners) -----
    def deterministic_action(self, obs: torch.Tensor) -> torch.Tensor:
        """squash(μ(s)): tanh of the mean on the action bounds, what evaluation acts with
        (OmniSafe's ``predict(deterministic=True)``)."""
        return squash(self.actor(obs)[0], self.action_low, self.action_high)

    def sample_action(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """ã = squash(u), u = μ(s) + σ(s)·ε by reparameterisation, and log π(ã|s) = log N(u; μ, σ²)
        − Σ log(1 − tanh²(u)) [O, and RLlib's TorchSquashedGaussian: the same density the env
        runners sample from, written out because torch.distributions costs more than the maths]."""
        return self._sample(*self.actor(obs))

    def _sample(self, mean: torch.Tensor, log_std: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        u = mean + log_std.exp() * self.standard_normal(mean)
        return squash(u, self.action_low, self.action_high), squashed_log_prob(u, mean, log_std)

    def standard_normal(self, like: torch.Tensor) -> torch.Tensor:
        """ε ~ N(0, I) shaped as ``like``: the noise of every reparameterised sample the learner
        draws (the reward target's a', the actor loss's ã). The one seam through which a test
        feeds a reference's recorded ε instead (tests/algorithms/sac_lag/test_sac_lag_golden.py
        replaces it on an instance)."""
        return torch.randn_like(like)

    # ----- training (learner) -----
    @override(TorchRLModule)
    def _forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        """Everything the critic losses need; the actor's own forward is :meth:`forward_actor`
        (it runs only on the policy-delay steps)."""
        obs, action, next_obs = batch[Columns.OBS], batch[Columns.ACTIONS], batch[Columns.NEXT_OBS]
        with torch.no_grad():
            next_mean, next_log_std = self.actor(next_obs)  # one actor forward for both targets
            next_action, logp_next = self._sample(next_mean, next_log_std)  # a' ~ π(·|s') [O]
            q_reward_next = self.target_reward_critics(next_obs, next_action)
            # The cost target's next action is deterministic: squash(μ(s')) [O, ddpg.py].
            next_det = squash(next_mean, self.action_low, self.action_high)
            q_cost_next = self.cost_values(self.target_cost_critic(next_obs, next_det))
        return {
            Q_REWARD: self.reward_critics(obs, action),
            Q_COST: self.cost_values(self.cost_critic(obs, action)),
            Q_REWARD_NEXT: q_reward_next,
            LOGP_NEXT: logp_next,
            Q_COST_NEXT: q_cost_next,
        }

    def forward_actor(self, obs: torch.Tensor) -> dict[str, torch.Tensor]:
        """The actor loss's inputs at s: log π(ã|s) and the critics at the reparameterised ã.

        The critics run frozen (:func:`frozen`), so the actor loss's gradient reaches the actor
        through ã and nothing else: its backward leaves the critics' gradients untouched and can
        share one backward with the critic losses."""
        action, logp = self.sample_action(obs)
        with frozen(self.reward_critics, self.cost_critic):
            return {
                LOGP: logp,
                Q_REWARD_PI: self.reward_critics(obs, action),
                Q_COST_PI: self.cost_values(self.cost_critic(obs, action)),
            }

    # ----- RLlib APIs -----
    @override(TargetNetworkAPI)
    def forward_target(self, batch: dict[str, Any]) -> dict[str, Any]:
        obs, action = batch[Columns.OBS], batch[Columns.ACTIONS]
        return {Q_REWARD: self.target_reward_critics(obs, action),
                Q_COST: self.cost_values(self.target_cost_critic(obs, action))}


@contextlib.contextmanager
def frozen(*nets: torch.nn.Module):
    """The networks' parameters do not require grad inside the block (OmniSafe freezes its critics
    the same way for the actor step): a forward there records no path to them. Their earlier
    graphs (the critic losses) keep theirs. Cheaper than a functional call with detached weights."""
    params = [p for net in nets for p in net.parameters() if p.requires_grad]
    for p in params:
        p.requires_grad_(False)
    try:
        yield
    finally:
        for p in params:
            p.requires_grad_(True)
