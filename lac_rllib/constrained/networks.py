"""Plain-torch networks the algorithms build from (docs/spec.md §3): LAC's Gaussian generator actor,
the Gaussian log-density and KL, the MLP builder and the critic ensemble (SAC-Lag's critics too).

The critic ensemble exists for the Langevin chain (docs/spec.md §1): the chain needs ∇_a of up to four
critics at every one of its T steps, so the critics are stored as one batched ensemble (one
``baddbmm`` per layer for all members), the state part of the first layer is computed once per
chain, and the action gradient comes from a hand-written backward pass that builds no autograd
graph and touches no parameter.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

_ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "mish": nn.Mish}
_ACT_FNS = {"tanh": torch.tanh, "relu": torch.relu, "mish": F.mish}
ACTIVATIONS = tuple(_ACTIVATIONS)  # the accepted names (LACParams.actor_activation)
_LOG_2PI = math.log(2.0 * math.pi)


def _check_activation(activation: str) -> None:
    if activation not in _ACTIVATIONS:
        raise ValueError(f"activation={activation!r}; accepted: {sorted(_ACTIVATIONS)}")


def mlp(in_dim: int, hidden: tuple[int, ...], out_dim: int, activation: str) -> nn.Sequential:
    """Linear → act → … → Linear (no activation on the output)."""
    _check_activation(activation)
    layers: list[nn.Module] = []
    for h in hidden:
        layers += [nn.Linear(in_dim, h), _ACTIVATIONS[activation]()]
        in_dim = h
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class GaussianActor(nn.Module):
    """π_φ(a|s) = N(μ_φ(s), diag σ²) with a state-independent log σ; no tanh squashing [P, C]."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...] = (256, 256),
                 activation: str = "tanh", log_std_init: float = -0.5,
                 mean_init_scale: float | None = None):
        super().__init__()
        self.mean_net = mlp(obs_dim, tuple(hidden), act_dim, activation)
        if mean_init_scale is not None:
            # [C]: a small head makes the first policy act near 0 whatever the observation, so
            # early data is not dominated by saturated actions. Scaling after nn.Linear's own
            # init draws the same random numbers as the unscaled network.
            head = self.mean_net[-1]
            with torch.no_grad():
                head.weight.mul_(mean_init_scale)
                head.bias.zero_()
        self.log_std = nn.Parameter(torch.full((act_dim,), float(log_std_init)))

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean = self.mean_net(obs)
        return mean, self.log_std.expand_as(mean)


def gaussian_log_prob(a: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log N(a; mean, diag exp(2·log_std)), summed over the action dimension → (B,)."""
    z = (a - mean) * torch.exp(-log_std)
    return (-0.5 * z.pow(2) - log_std - 0.5 * _LOG_2PI).sum(-1)


def gaussian_kl(mean_p: torch.Tensor, log_std_p: torch.Tensor,
                mean_q: torch.Tensor, log_std_q: torch.Tensor) -> torch.Tensor:
    """Closed-form KL(p ‖ q) of two diagonal Gaussians, summed over dimensions → (B,)."""
    var_ratio = torch.exp(2.0 * (log_std_p - log_std_q))
    mahal = (mean_p - mean_q).pow(2) * torch.exp(-2.0 * log_std_q)
    return (log_std_q - log_std_p + 0.5 * (var_ratio + mahal - 1.0)).sum(-1)


def reward_rows(q: torch.Tensor, n_reward: int) -> torch.Tensor:
    """Q_R1..Q_Rn: the reward critics' rows of a critic-ensemble output q (E, ...), a view.

    A plain function of a tensor and an int, so torch.compile traces it (lac_rllib.algorithms.lac.energy).
    """
    return q[:n_reward]


def cost_rows(q: torch.Tensor, n_reward: int) -> torch.Tensor:
    """Q_C1..Q_Cm: the cost critics' rows of a critic-ensemble output q (E, ...), a view (the
    rows after the ``n_reward`` reward critics; empty when the ensemble has no cost critic)."""
    return q[n_reward:]


def max_per_constraint(q_c: torch.Tensor, k: int) -> torch.Tensor:
    """max_j Q_Ckj of each of K constraints from the cost rows (K·m, ...) → (K, ...): constraint k's
    m critics are rows [k·m, (k+1)·m) (a critic ensemble with ``n_cost`` = K·m)."""
    return q_c.reshape(k, -1, *q_c.shape[1:]).max(1).values


def act_and_grad(name: str, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Activation value and its derivative at the pre-activation z (for the manual backward)."""
    if name == "mish":
        # mish(z) = z·t, t = tanh(softplus(z)); mish'(z) = t + z·σ(z)·(1 − t²). With e = e^z and
        # n = e(e+2): t = n/(n+2) and σ(z)·(1 − t²) = 4e(e+1)/(n+2)². One exp and in-place ops
        # instead of softplus + tanh + sigmoid: about 2x cheaper, and these element-wise ops are
        # a third of a chain step. Clamping z at 20 is exact to float64 precision (t = 1 there).
        e = z.clamp(max=20.0).exp_()
        r = (e + 2.0).mul_(e)                                  # n
        t = r / (r + 2.0)
        r.add_(2.0).reciprocal_()                              # 1/(n+2)
        return z * t, (e + 1.0).mul_(e).mul_(r).mul_(r).mul_(z).mul_(4.0).add_(t)
    if name == "tanh":
        t = torch.tanh(z)
        return t, 1.0 - t * t
    if name == "relu":
        return torch.relu(z), (z > 0).to(z.dtype)
    raise ValueError(f"activation={name!r}; accepted: {sorted(_ACTIVATIONS)}")


class CriticEnsemble(nn.Module):
    """E = n_reward + n_cost independent Q(s, a) MLPs stored as one batched ensemble.

    Layer k holds ``weights[k]`` of shape (E, in, out) and ``biases[k]`` of shape (E, 1, out), so
    one ``baddbmm`` evaluates every member. Rows ``[:n_reward]`` are reward critics, rows
    ``[n_reward:]`` cost critics: read them with :func:`reward_rows` / :func:`cost_rows`. The
    first layer's input is concat(obs, act); its weight rows ``[:obs_dim]`` act on the state and
    ``[obs_dim:]`` on the action, which is what lets the chain compute the state part once
    (``project_state``) and only redo the action part per step.
    """

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...] = (256, 256, 256),
                 n_reward: int = 2, n_cost: int = 2, activation: str = "mish",
                 matmul_dtype: torch.dtype = torch.float32):
        super().__init__()
        _check_activation(activation)
        if matmul_dtype not in (torch.float32, torch.bfloat16):
            raise ValueError(f"matmul_dtype={matmul_dtype}; accepted: torch.float32, torch.bfloat16")
        #: The input dtype of :meth:`forward`'s hidden layers (SAC-Lag's ``critic_dtype``).
        self.matmul_dtype = matmul_dtype
        if n_reward < 1 or n_cost < 0:
            raise ValueError(f"n_reward={n_reward}, n_cost={n_cost}; need n_reward ≥ 1, n_cost ≥ 0")
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.n_reward, self.n_cost = n_reward, n_cost
        self.n_members = n_reward + n_cost
        self.activation = activation
        dims = [obs_dim + act_dim, *hidden, 1]
        # Build each member from real nn.Linear layers (member by member, layer by layer, the RNG
        # order of E separate MLPs) so the initialisation is exactly nn.Linear's.
        per_member = [[nn.Linear(i, o) for i, o in zip(dims[:-1], dims[1:])]
                      for _ in range(self.n_members)]
        self.weights = nn.ParameterList(
            nn.Parameter(torch.stack([m[k].weight.detach().t() for m in per_member]).contiguous())
            for k in range(len(dims) - 1))
        self.biases = nn.ParameterList(
            nn.Parameter(torch.stack([m[k].bias.detach()[None] for m in per_member]).contiguous())
            for k in range(len(dims) - 1))

    # --- forward pieces -------------------------------------------------------------------
    def project_state(self, obs: torch.Tensor) -> torch.Tensor:
        """First-layer state part W_s·s + b → (E, B, H1); constant along a Langevin chain."""
        w_s = self.weights[0][:, : self.obs_dim]
        return torch.baddbmm(self.biases[0], obs.expand(self.n_members, *obs.shape), w_s)

    def _first_preact(self, proj: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        w_a = self.weights[0][:, self.obs_dim:]
        return torch.baddbmm(proj, act.expand(self.n_members, *act.shape), w_a)

    def _tail(self, z: torch.Tensor) -> torch.Tensor:
        fn = _ACT_FNS[self.activation]
        for w, b in zip(list(self.weights)[1:], list(self.biases)[1:]):
            z = torch.baddbmm(b, fn(z), w)
        return z.squeeze(-1)

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        """Q values of every member → (E, B).

        With ``matmul_dtype`` bfloat16 the hidden layers multiply in bfloat16 (the weights cast at
        each call: the parameters, their gradients and the optimizer stay float32) and the output
        layer in float32, so that Q itself is not rounded to bfloat16's 8 bits; float32 is the
        plain forward, unchanged."""
        x = torch.cat([obs, act], dim=-1)
        x = x.expand(self.n_members, *x.shape)
        if self.matmul_dtype == torch.float32:
            return self._tail(torch.baddbmm(self.biases[0], x, self.weights[0]))
        dtype, fn = self.matmul_dtype, _ACT_FNS[self.activation]
        weights, biases = list(self.weights), list(self.biases)
        z = x.to(dtype)
        for w, b in zip(weights[:-1], biases[:-1]):
            z = fn(torch.baddbmm(b.to(dtype), z, w.to(dtype)))
        return torch.baddbmm(biases[-1], z.float(), weights[-1]).squeeze(-1)

    # --- manual action gradient -------------------------------------------------------------
    @torch.no_grad()
    def q_and_action_grad(self, proj: torch.Tensor, act: torch.Tensor,
                          coef) -> tuple[torch.Tensor, torch.Tensor]:
        """Q (E, B) and Σ_e coef[e, b]·∇_a Q_e(s_b, a_b) → (B, A), by a hand-written backward.

        ``coef`` is an (E, B) tensor, or a callable q → (E, B) when the weights depend on the Q
        values themselves (the chain's argmin/argmax selection). No autograd graph is built, so
        no parameter can receive a gradient and the cost is two batched matmuls per layer.
        """
        z = self._first_preact(proj, act)
        weights, biases = list(self.weights), list(self.biases)  # (slicing a ParameterList is slow)
        derivs = []
        for w, b in zip(weights[1:], biases[1:]):
            h, dh = act_and_grad(self.activation, z)
            derivs.append(dh)
            z = torch.baddbmm(b, h, w)
        q = z.squeeze(-1)
        c = coef(q) if callable(coef) else coef
        g = c.to(q.dtype).unsqueeze(-1)                       # dL/dz_out, (E, B, 1)
        for w, dh in zip(reversed(weights[1:]), reversed(derivs)):
            g = torch.bmm(g, w.transpose(1, 2)).mul_(dh)      # back through Linear, then act
        # Only the action rows of the first layer lead back to a; the state rows are constant.
        grad = torch.bmm(g, weights[0][:, self.obs_dim:].transpose(1, 2)).sum(0)
        return q, grad
