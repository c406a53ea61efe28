"""LACTorchRLModule: the networks of LAC and their forward passes (losses live in the Learner).

- ``actor``: the Gaussian generator π_φ (docs/spec.md §3). Inference acts with its mean, exploration
  samples it (RLlib's TorchDiagGaussian over [mean, log_std]).
- ``critics``: 2 reward + 2 cost critics as one batched ensemble (docs/spec.md §2); with K
  constraints (``num_constraints``) 2 cost critics each, ν then (K,).
- ``target_actor`` / ``target_critics``: Polyak copies π_φ', Q' (Algorithm 2, lines 11-13).
- ``nu``: the Lagrange multiplier ν (eq. 14). It is a buffer of the module, so it travels with
  the weights (the Learner's state, checkpoints) and a restored module can run the chain at
  deployment. The Learner is the only writer.

Only the actor (and ν) exist on env runners: critics and targets are non-inference attributes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.lac.langevin import ChainResult, ChainSettings, langevin_chain
from lac_rllib.constrained.lagrange import initial_nus
from lac_rllib.constrained.networks import CriticEnsemble, GaussianActor
from lac_rllib.constrained.precision import resolve_dtype
from lac_rllib.families.off_policy.module import ActorCriticRLModule

# Keys of the forward_train output, declared once.
Q_PRED = "q_pred"  # (E, B) online Q(s, a), rows [:n_reward] reward critics
Q_TARGET_NEXT = "q_target_next"  # (E, B) target Q'(s', ã')
ACTOR_MEAN, ACTOR_LOG_STD = "actor_mean", "actor_log_std"  # π_φ(·|s*)
TARGET_MEAN, TARGET_LOG_STD = "target_mean", "target_log_std"  # π_φ'(·|s*)
ACTOR_TARGET_ACTION = "actor_target_action"  # ã, the maximum-likelihood target of eq. (15)
CHAIN = "chain"  # ChainResult of the critic-target chain


class LACTorchRLModule(ActorCriticRLModule):
    TARGETS = {"actor": "target_actor", "critics": "target_critics"}

    @override(TorchRLModule)
    def setup(self):
        cfg = self.model_config
        obs_dim = int(self.observation_space.shape[0])
        act_dim = int(self.action_space.shape[0])
        self.actor = GaussianActor(
            obs_dim, act_dim, hidden=tuple(cfg["actor_hidden"]),
            activation=cfg["actor_activation"], log_std_init=cfg["log_std_init"],
            mean_init_scale=cfg["actor_mean_init_scale"],
        )
        k = int(cfg.get("num_constraints", 1))  # K constraints: ν (K,) and twin cost critics each
        self.register_buffer("nu", initial_nus(cfg, k))
        if not self.inference_only:
            self.critics = CriticEnsemble(obs_dim, act_dim, hidden=tuple(cfg["critic_hidden"]),
                                          **({"n_cost": 2 * k} if k > 1 else {}))
        self.chain_settings = chain_settings(cfg, self.action_space)

    # ----- acting (env runners) -----
    def deterministic_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The generator's mean μ_φ(s): what inference acts with (``lac-eval --actions generator``)."""
        return self.actor(obs)[0]

    # ----- evaluation (lac-eval --actions) -----
    def evaluation_action(self, obs: torch.Tensor, mode: str, *, generator=None, steps=None,
                          step_size=None) -> tuple[torch.Tensor, dict[str, float]]:
        """The action ``lac-eval --actions MODE`` takes at ``obs`` (1, obs_dim) and the mode's
        per-state diagnostics: "generator", μ_φ(s); "langevin", Algorithm 1 started from the
        TARGET actor π_φ'(·|s) with the online critics and ν, noise from ``generator``, T and η
        the checkpoint's unless given, with the energy at the chain's start and end and the
        distance it moved the action (docs/spec.md §1)."""
        if mode == "generator":
            return self.deterministic_action(obs), {}
        t_mean, t_log_std = self.target_actor(obs)
        chain = self.langevin(obs, t_mean, t_log_std, steps=steps, step_size=step_size, generator=generator)
        return chain.action, {"energy_generator": float(chain.energy_start[0]),
                              "energy_refined": float(chain.energy_end[0]),
                              "action_displacement": float(chain.displacement[0])}

    def evaluation_info(self, mode: str, *, steps=None, step_size=None) -> dict:
        """What an evaluation in ``mode`` ran with, for its result: the chain's T, η and ν."""
        if mode == "generator":
            return {}
        return {"langevin_steps": steps or self.chain_settings.steps,
                "langevin_step_size": step_size or self.chain_settings.step_size, "nu": self.nu.tolist()}

    # ----- training (learner) -----
    @override(TorchRLModule)
    def _forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        obs, next_obs = batch[Columns.OBS], batch[Columns.NEXT_OBS]
        with torch.no_grad():
            t_mean_next, t_log_std_next = self.target_actor(next_obs)
            # ã' = Langevin chain at s' started from π_φ'(·|s') (Algorithm 2, line 7).
            chain = self.langevin(next_obs, t_mean_next, t_log_std_next)
            q_target_next = self.target_critics(next_obs, chain.action)  # eq. (13)
        out = {
            Q_PRED: self.critics(obs, batch[Columns.ACTIONS]),
            Q_TARGET_NEXT: q_target_next,
            CHAIN: chain,
        }
        if self.model_config["actor_chain_at"] == "next":
            # One chain per minibatch: the actor fits the critic's target action at s' [C].
            s_star, target_action, t_mean, t_log_std = next_obs, chain.action, t_mean_next, t_log_std_next
        else:
            # eq. (15) as written: a second chain at s.
            s_star = obs
            with torch.no_grad():
                t_mean, t_log_std = self.target_actor(obs)
                target_action = self.langevin(obs, t_mean, t_log_std).action
        out[ACTOR_MEAN], out[ACTOR_LOG_STD] = self.actor(s_star)
        out[TARGET_MEAN], out[TARGET_LOG_STD] = t_mean, t_log_std
        out[ACTOR_TARGET_ACTION] = target_action
        return out

    def langevin(self, obs, mean, log_std, *, steps=None, step_size=None, generator=None,
                 noise=None) -> ChainResult:
        """Algorithm 1 at ``obs`` with the online critics, ν and this module's chain settings.

        ``mean``/``log_std`` are π_φ'(·|obs); ``steps``/``step_size`` override T and η. ``noise``
        (T+1, B, A), optional: the chain's draws, z₀ of the start then z₁..z_T
        (:func:`~lac_rllib.algorithms.lac.langevin.langevin_chain`), for a step compared draw for
        draw with another implementation's (tests/algorithms/lac/test_lac_golden.py).
        """
        settings = (self.chain_settings if steps is None and step_size is None
                    else self.chain_settings.with_steps(steps, step_size))
        return langevin_chain(self.critics, obs, mean, log_std, self.nu, settings, noise=noise,
                              generator=generator)

    # ----- RLlib APIs -----
    @override(TargetNetworkAPI)
    def forward_target(self, batch: dict[str, Any]) -> dict[str, Any]:
        return {"q": self.target_critics(batch[Columns.OBS], batch[Columns.ACTIONS])}


def chain_settings(cfg: dict, action_space) -> ChainSettings:
    """The chain's settings from the module's model config (LAC's fields), made once per module."""
    clamp = cfg["langevin_clamp"]
    return ChainSettings(
        steps=cfg["langevin_steps"], step_size=cfg["langevin_step_size"], temperature=cfg["temperature"],
        logp_weight=cfg["logp_weight"], start=cfg["langevin_start"],
        low=torch.tensor(np.array(action_space.low), dtype=torch.float32) if clamp else None,
        high=torch.tensor(np.array(action_space.high), dtype=torch.float32) if clamp else None,
        grad_clip=cfg["langevin_grad_clip"], grad_clip_mode=cfg["langevin_grad_clip_mode"],
        fused=cfg["langevin_fused"], dtype=resolve_dtype(cfg["langevin_dtype"]),
    )
