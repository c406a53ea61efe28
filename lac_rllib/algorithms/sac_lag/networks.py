"""SAC-Lag's actor, OmniSafe's ``GaussianSACActor``: a tanh-squashed Gaussian with a state-dependent
log σ, and the RLlib action distribution that acts with it on the env runners.

The critics are LAC's :class:`~lac_rllib.constrained.networks.CriticEnsemble` (ReLU, one
ensemble for the two reward critics and one for the cost critic); nothing here is new about them.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from ray.rllib.core.distribution.torch.torch_distribution import TorchDeterministic, TorchSquashedGaussian
from torch import nn

from lac_rllib.constrained.networks import gaussian_log_prob, mlp


class SquashedGaussianActor(nn.Module):
    """μ(s), log σ(s) from one MLP (obs → hidden → 2·A) [O]; log σ clamped to [log_std_min,
    log_std_max] ([O]: [−20, 2]). The action is a = squash(u), u ~ N(μ, σ²) (:func:`squash`)."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...], activation: str,
                 log_std_min: float, log_std_max: float):
        super().__init__()
        self.net = mlp(obs_dim, tuple(hidden), 2 * act_dim, activation)
        self.log_std_min, self.log_std_max = float(log_std_min), float(log_std_max)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, log_std = self.net(obs).chunk(2, dim=-1)
        return mean, log_std.clamp(self.log_std_min, self.log_std_max)


#: log 2 of the tanh Jacobian. OmniSafe's actor holds it as a float32 buffer (gaussian_sac_actor.py
#: ``register_buffer('_log2', torch.log(torch.tensor(2.0)))``): in a float32 step the same number as
#: this one; widened by its ``.double()`` it stays 1.9e-9 below log 2, and the float64 golden test
#: (tests/algorithms/sac_lag/test_sac_lag_golden.py) sets this name to that value to compare to 1e-11.
LOG_2 = math.log(2.0)


def squash(u: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """tanh(u) mapped affinely onto [low, high], as RLlib's TorchSquashedGaussian does (OmniSafe acts
    in [−1, 1] and rescales in its env wrapper: the same map)."""
    return low + (torch.tanh(u) + 1.0) * 0.5 * (high - low)


def squashed_log_prob(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log π(squash(u)) for u ~ N(mean, σ²), summed over the action → (B,): the Gaussian's density
    minus log|d tanh/du| = 2·(log 2 − u − softplus(−2u)), the stable form OmniSafe and RLlib use.
    The affine map onto the bounds adds a constant, left out as both leave it out."""
    jacobian = 2.0 * (LOG_2 - u - F.softplus(-2.0 * u))
    return gaussian_log_prob(u, mean, log_std) - jacobian.sum(-1)


def squashed_gaussian(low: torch.Tensor, high: torch.Tensor) -> type:
    """RLlib's TorchSquashedGaussian bound to the action space ``[low, high]``, for
    ``RLModule.action_dist_cls``. Two changes, both so that the env runners act with exactly the
    policy the learner trains: ``from_logits`` takes log σ as the module clamped it (RLlib's own
    clamps it again to [−5, 2], cutting OmniSafe's lower bound −20), and ``to_deterministic`` (RLlib's
    inference, ``explore=False``) acts with squash(μ), where RLlib's would return the raw μ."""

    class BoundedSquashedGaussian(TorchSquashedGaussian):
        @classmethod
        def from_logits(cls, logits: torch.Tensor, **kwargs) -> "BoundedSquashedGaussian":
            mean, log_std = logits.chunk(2, dim=-1)
            return cls(loc=mean, scale=log_std.exp(), low=low, high=high)

        def to_deterministic(self) -> TorchDeterministic:
            return TorchDeterministic(loc=squash(self.loc, low, high))

    return BoundedSquashedGaussian
