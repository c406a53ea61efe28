"""The LAC energy and its action gradient, the work of every Langevin step (eq. 9):

    E(s, a) = (1/λ)·(ν·max_j Q_Cj(s, a) − min_j Q_Rj(s, a)) − w·log π_φ'(a|s),
    ∇_a E   = Σ_e coef_e·∇_a Q_e(s, a) + w·(a − μ)/σ²,

where coef is −1/λ on the argmin reward critic and +ν/λ on the argmax cost critic of each sample
(min and max are piecewise: the subgradient flows through the selected member only). With K
constraints ν is (K,) and the cost term Σ_k ν_k·max_j Q_Ckj, each constraint's twin cost critics
their own group of rows (+ν_k/λ on each group's argmax).

One formula, two ways to run the critics' backward pass, chosen by ``langevin_fused``:
- :func:`eager_grad_fn`: ``CriticEnsemble.q_and_action_grad``, a hand-written backward with
  in-place element-wise ops and ``baddbmm`` (in eager mode the in-place Mish derivative is ~2x
  cheaper than the out-of-place one);
- :func:`make_grad_fn` (``compiled=True``): :func:`energy_and_grad`, the same backward as one pure
  function so that ``torch.compile`` (Inductor) can fuse each layer's element-wise work into one
  loop (in eager mode those are ~15 passes over each (E, B, H) tensor, about a third of a step).
Inductor cannot trace the in-place version whole, and the two round floats differently (within
1e-5 on the end points, tests/algorithms/lac/test_energy.py), so making either path the other's
would change what every seeded run and the committed sweep results reproduce. What they share, the
selection of the critics, the energy and the Gaussian term, is written once below and used by both.

``dtype="bfloat16"`` runs the matmuls on bfloat16 inputs (the BLAS accumulates in float32);
the action, energy, gradient and the chain's update stay float32. Whether that pays depends on
the CPU (docs/speed.md): only with native bf16 matmuls (AVX512-BF16, AMX).

Plain torch, no RLlib.
"""

from __future__ import annotations

import logging
import math

import torch

from lac_rllib.constrained import networks
from lac_rllib.constrained.networks import CriticEnsemble, cost_rows, max_per_constraint, reward_rows
from lac_rllib.constrained.precision import DTYPES, TORCH_DTYPES

logger = logging.getLogger(__name__)


# ----- The pieces both paths share -----
def gaussian_terms(mean: torch.Tensor, log_std: torch.Tensor, logp_weight: float):
    """(μ, 1/σ², the a-free part of −w·log π) for a chain: −w·log π(a) = w·(½ Σ (a−μ)²/σ² + Σ log σ
    + (A/2)·log 2π), of which only the first term depends on a."""
    mean, log_std = mean.detach(), log_std.detach()
    inv_var = torch.exp(-2.0 * log_std)
    logp_const = logp_weight * (log_std.sum(-1) + 0.5 * mean.shape[-1] * math.log(2 * math.pi))
    return mean, inv_var, logp_const


def selection(q: torch.Tensor, n_reward: int, inv_lam: float, nu, cols: torch.Tensor) -> torch.Tensor:
    """coef (E, B): −1/λ on each sample's argmin reward critic, +ν/λ on its argmax cost critic (with
    K constraints, ν (K,): +ν_k/λ on the argmax of each constraint's group of cost critics)."""
    coef = torch.zeros_like(q)
    coef[reward_rows(q, n_reward).argmin(0), cols] = -inv_lam
    if q.shape[0] > n_reward and nu.dim() == 0:
        coef[n_reward + cost_rows(q, n_reward).argmax(0), cols] = nu * inv_lam
    elif q.shape[0] > n_reward:
        k = nu.shape[0]
        group = (q.shape[0] - n_reward) // k
        first = n_reward + group * torch.arange(k, device=q.device)[:, None]
        rows = first + cost_rows(q, n_reward).reshape(k, group, -1).argmax(1)  # (K, B)
        coef[rows, cols.expand(k, -1)] = (nu * inv_lam).to(q.dtype)[:, None].expand(k, q.shape[1])
    return coef


def energy_of(q: torch.Tensor, diff: torch.Tensor, inv_var, logp_const, nu, *, inv_lam: float,
              logp_weight: float, n_reward: int) -> torch.Tensor:
    """E(s, a) (B,) from the critics' Q (E, B) and a − μ (B, A)."""
    energy = -inv_lam * reward_rows(q, n_reward).min(0).values
    if q.shape[0] > n_reward and nu.dim() == 0:
        energy = energy + nu * inv_lam * cost_rows(q, n_reward).max(0).values
    elif q.shape[0] > n_reward:  # K constraints: Σ_k ν_k·max_j Q_Ckj
        energy = energy + inv_lam * (nu[:, None] * max_per_constraint(cost_rows(q, n_reward), nu.shape[0])).sum(0)
    return energy + logp_weight * 0.5 * (diff * diff * inv_var).sum(-1) + logp_const


# ----- Eager: the hand-written backward of CriticEnsemble -----
def eager_grad_fn(critics: CriticEnsemble, proj: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor, *,
                  temperature: float, nu, logp_weight: float):
    """grad_fn(a) -> (E (B,), ∇_a E (B, A)) for ``langevin.run_chain``; ``proj`` (the critics' first
    layer at s), ``mean`` and ``log_std`` are fixed along the chain."""
    nr, inv_lam = critics.n_reward, 1.0 / temperature
    nu = torch.as_tensor(nu, dtype=mean.dtype, device=mean.device)
    mean, inv_var, logp_const = gaussian_terms(mean, log_std, logp_weight)
    cols = torch.arange(mean.shape[0], device=mean.device)

    def grad_fn(a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q, grad_q = critics.q_and_action_grad(proj, a, lambda q: selection(q, nr, inv_lam, nu, cols))
        diff = a - mean
        energy = energy_of(q, diff, inv_var, logp_const, nu, inv_lam=inv_lam, logp_weight=logp_weight, n_reward=nr)
        return energy, grad_q + logp_weight * diff * inv_var   # ∇(−w log π) = w(a−μ)/σ²

    return grad_fn


# ----- Fused: one pure function for torch.compile -----
def _act_and_grad(name: str, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Activation and its derivative at z, out-of-place (Inductor fuses them into one loop); Mish
    written here because networks' is in place."""
    if name == "mish":
        # mish(z) = z·t, t = tanh(softplus(z)) = n/(n+2) with n = e(e+2), e = exp(z);
        # mish'(z) = t + z·σ(z)(1 − t²) = t + 4·z·e(e+1)/(n+2)². z is clamped at 20 for exp,
        # exact to float precision there (t = 1).
        e = torch.exp(torch.clamp(z, max=20.0))
        n = e * (e + 2.0)
        r = 1.0 / (n + 2.0)
        t = n * r
        return z * t, t + 4.0 * z * e * (e + 1.0) * r * r
    return networks.act_and_grad(name, z)  # tanh and relu are out-of-place there already


def _mm(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Batched x @ w in w's dtype, returned as float32."""
    return torch.bmm(x.to(w.dtype), w).to(torch.float32)


def energy_and_grad(a, proj, w_a, ws, ws_t, bs, mean, inv_var, logp_const, nu, *, inv_lam: float,
                    logp_weight: float, n_reward: int, activation: str):
    """E(s, a) (B,) and ∇_a E (B, A), the critics' backward written out.

    ``proj`` (E, B, H1) is the critics' first layer at s (constant along a chain), ``w_a``
    (E, A, H1) its action rows; ``ws``/``bs`` the later layers' weights/biases and ``ws_t`` the
    weights transposed, all in the matmul dtype except ``bs`` and ``w_a`` (float32).
    """
    n_members = proj.shape[0]
    z = torch.baddbmm(proj, a.expand(n_members, *a.shape), w_a)
    derivs = []
    for w, b in zip(ws, bs):
        h, dh = _act_and_grad(activation, z)
        derivs.append(dh)
        z = _mm(h, w) + b
    q = z.squeeze(-1)                                                # (E, B)
    coef = selection(q, n_reward, inv_lam, nu, torch.arange(q.shape[1], device=q.device))
    diff = a - mean
    energy = energy_of(q, diff, inv_var, logp_const, nu, inv_lam=inv_lam, logp_weight=logp_weight,
                       n_reward=n_reward)
    g = coef.unsqueeze(-1)                                           # dL/dz_out, (E, B, 1)
    for w_t, dh in zip(reversed(ws_t), reversed(derivs)):
        g = _mm(g, w_t) * dh                                         # back through Linear, then act
    grad = torch.bmm(g, w_a.transpose(1, 2)).sum(0)                  # only the action rows lead to a
    return energy, grad + logp_weight * diff * inv_var               # ∇(−w log π) = w(a−μ)/σ²


_compiled = None
_compile_failed = False


def _compiled_fn():
    """``energy_and_grad`` under torch.compile, built once per process; None if unavailable."""
    global _compiled, _compile_failed
    if _compiled is None and not _compile_failed:
        _compiled = torch.compile(energy_and_grad, dynamic=False, fullgraph=True)
    return _compiled


def make_grad_fn(critics, proj: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor, *,
                 temperature: float, nu, logp_weight: float, compiled: bool, dtype: str = "float32"):
    """grad_fn(a) -> (E, ∇_a E) for ``langevin.run_chain``, on the pure-function path.

    ``compiled``: through torch.compile (falls back to eager, once logged, if compiling fails,
    e.g. without a C++ compiler). ``dtype``: the matmuls' input dtype (one of DTYPES).
    """
    if dtype not in DTYPES:
        raise ValueError(f"dtype={dtype!r}; accepted: {' | '.join(DTYPES)}")
    mm_dtype = TORCH_DTYPES[dtype]
    weights, biases = [w.detach() for w in critics.weights], [b.detach() for b in critics.biases]
    w_a = weights[0][:, critics.obs_dim:]
    ws = [w.to(mm_dtype) for w in weights[1:]]
    ws_t = [w.transpose(1, 2).contiguous() for w in ws]
    mean, inv_var, logp_const = gaussian_terms(mean, log_std, logp_weight)
    nu = torch.as_tensor(nu, dtype=mean.dtype, device=mean.device)
    kw = dict(inv_lam=1.0 / temperature, logp_weight=float(logp_weight), n_reward=critics.n_reward,
              activation=critics.activation)
    args = (proj, w_a, ws, ws_t, biases[1:], mean, inv_var, logp_const, nu)

    def grad_fn(a: torch.Tensor):
        global _compile_failed
        fn = _compiled_fn() if compiled else None
        if fn is not None:
            try:
                return fn(a, *args, **kw)
            except Exception as e:  # Inductor raises many kinds; the eager path is exact
                _compile_failed = True
                logger.warning("torch.compile of the Langevin step failed (%s: %s); the chain runs eagerly",
                               type(e).__name__, str(e).splitlines()[0] if str(e) else "")
        return energy_and_grad(a, *args, **kw)

    return grad_fn
