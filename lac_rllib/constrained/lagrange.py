"""The Lagrange multiplier ν of a constrained algorithm, as one object (docs/spec.md §4).

A :class:`LagrangeMultiplier` owns ν's update: the projected step of eq. (14),

    ν ← min( ν_max, max(0, ν + α_ν·(Ĵ_C − b)) ),

with the step itself pluggable (a :class:`StepRule`: eq. (14)'s gradient step, OmniSafe's Adam
step, safety-starter-agents' Adam on softplus⁻¹(ν); docs/spec.md §4), the authors' adaptive bound ν_max
(:class:`AdaptiveBound`, [C]), a fixed one (:class:`FixedBound`) or none, and its checkpoint
state. Its *value* is the RLModule's ν buffer, which the multiplier is the only writer of: the
buffer travels with the module's weights, so env runners, checkpoints and a restored policy
(``--actions langevin``) all see the same ν.

Plain torch, no RLlib: the learners call it (LAC's, SAC-Lag's, families/on_policy/lagrangian.py).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import torch

from lac_rllib.constrained.fields import NAME, NON_NEGATIVE, or_none, param


class StepRule(Protocol):
    """One step of ν from the episode cost: returns the new ν *before* the projection onto
    [0, ν_max] (the multiplier projects)."""

    def step(self, nu: float, episode_cost: float, cost_limit: float) -> float: ...

    def get_state(self) -> dict: ...

    def set_state(self, state: dict) -> None: ...


class GradientStep:
    """Eq. (14): ν + α_ν·(Ĵ_C − b), gradient ascent on the Lagrangian in ν [P, C]."""

    def __init__(self, lr: float):
        self.lr = float(lr)

    def step(self, nu: float, episode_cost: float, cost_limit: float) -> float:
        return nu + self.lr * (episode_cost - cost_limit)

    def get_state(self) -> dict:
        return {}

    def set_state(self, state: dict) -> None:
        pass


class AdamStep:
    """OmniSafe's ``common/lagrange.py``: Adam on the loss −ν·(Ĵ_C − b), i.e. on the gradient
    g = −(Ĵ_C − b), with torch.optim.Adam's update (bias-corrected moments m, v over t steps)."""

    def __init__(self, lr: float, betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        self.lr, self.betas, self.eps = float(lr), (float(betas[0]), float(betas[1])), float(eps)
        self.m, self.v, self.t = 0.0, 0.0, 0

    def step(self, nu: float, episode_cost: float, cost_limit: float) -> float:
        b1, b2 = self.betas
        g = -(episode_cost - cost_limit)
        self.t += 1
        self.m = b1 * self.m + (1 - b1) * g
        self.v = b2 * self.v + (1 - b2) * g * g
        # torch.optim.Adam: ν − (lr / (1 − β₁ᵗ))·m / (√v / √(1 − β₂ᵗ) + ε)
        denom = math.sqrt(self.v) / math.sqrt(1 - b2**self.t) + self.eps
        return nu - self.lr / (1 - b1**self.t) * self.m / denom

    def get_state(self) -> dict:
        return {"m": self.m, "v": self.v, "t": self.t}

    def set_state(self, state: dict) -> None:
        self.m, self.v, self.t = float(state["m"]), float(state["v"]), int(state["t"])


def softplus(x: float) -> float:
    return max(x, 0.0) + math.log1p(math.exp(-abs(x)))


class SoftplusAdamStep:
    """[S] run_agent.py: ν = softplus(p), p₀ = softplus⁻¹(ν₀), Adam on the loss −p·(Ĵ_C − b) (the loss
    is on p itself: PPO-L sets ``penalty_param_loss``). ν ≥ 0 by construction."""

    def __init__(self, lr: float, nu_init: float):
        self.adam = AdamStep(lr)
        self.p = math.log(max(math.expm1(nu_init), 1e-8))

    def step(self, nu: float, episode_cost: float, cost_limit: float) -> float:
        self.p = self.adam.step(self.p, episode_cost, cost_limit)
        return softplus(self.p)

    def get_state(self) -> dict:
        return {"p": self.p, "adam": self.adam.get_state()}

    def set_state(self, state: dict) -> None:
        self.p = float(state["p"])
        self.adam.set_state(state["adam"])


class HeldStep:
    """ν held where it is, every step: a fixed-multiplier run (``nu_fixed``)."""

    def step(self, nu: float, episode_cost: float, cost_limit: float) -> float:
        return nu

    def get_state(self) -> dict:
        return {}

    def set_state(self, state: dict) -> None:
        pass


@dataclasses.dataclass
class FixedMultiplierParams:
    """The field every algorithm with a Lagrange multiplier has (LAC, SAC-Lag and the on-policy
    Lagrangian family): ν frozen for a whole run, the runs that trace a task's empirical return-cost
    frontier (docs/sweeps.md, "The fixed-multiplier frontier")."""

    nu_fixed: float | None = param(None, accepts=or_none(NON_NEGATIVE))
    """ν for the whole run, never stepped nor bounded (the learning rate, bound and ν₀ of the
    multiplier then change nothing); None = the multiplier learns [D]."""
    nu_fixed_constraint: str | None = param(None, accepts=or_none(NAME))
    """With several constraints and ``nu_fixed``: the one constraint whose ν_k it holds, the others'
    multipliers learning by the algorithm's rule (the frontier along one constraint); None: every ν_k
    held at ``nu_fixed``."""


def initial_nu(model_config: dict[str, Any]) -> float:
    """ν₀ of a module: ``nu_fixed`` where set, else ``nu_init``."""
    fixed = model_config.get("nu_fixed")
    return float(fixed if fixed is not None else model_config["nu_init"])


#: A module's model config key: the index of the one constraint ``nu_fixed`` holds (nu_fixed_constraint).
NU_FIXED_INDEX = "nu_fixed_index"


def initial_nus(model_config: dict[str, Any], k: int) -> torch.Tensor:
    """A module's ν buffer at the start: 0-d with one constraint (:func:`initial_nu`), (K,) with K,
    each ν_k at ``nu_fixed`` where it holds that one (``nu_fixed_index``) or all, else ``nu_init``."""
    if k == 1:
        return torch.tensor(initial_nu(model_config))
    index = model_config.get(NU_FIXED_INDEX)
    if index is None:
        return torch.full((k,), initial_nu(model_config))
    nus = torch.full((k,), float(model_config["nu_init"]))
    nus[int(index)] = float(model_config["nu_fixed"])
    return nus


class AdaptiveBound:
    """[C]'s upper bound on ν, from the iteration's mean critic targets ȳ_R, ȳ_C (docs/spec.md §4):

        ν_max = 2                                   until the first iteration ends,
        ν_max = 2·|ȳ_R| / max(|ȳ_C|, 1e-8)          after each iteration,

    so the cost term of the chain's energy cannot outweigh the reward term while the reward
    critic is still small. ȳ are means over *every* minibatch of the iteration (:meth:`observe`
    each one), not the last one's."""

    def __init__(self, initial: float = 2.0, ratio: float = 2.0):
        self.value, self.ratio = float(initial), float(ratio)
        self._sums = torch.zeros(3)  # Σ y_R, Σ y_C, count over the current iteration

    def start_iteration(self) -> None:
        self._sums.zero_()

    def observe(self, y_r: torch.Tensor, y_c: torch.Tensor) -> None:
        self._sums += torch.stack([y_r.sum(), y_c.sum(), torch.tensor(float(len(y_r)))])

    def end_iteration(self) -> tuple[float, float] | None:
        """Set the next bound; returns (ȳ_R, ȳ_C), or None if no minibatch was observed."""
        if self._sums[2] == 0:
            return None
        mean_r, mean_c = (self._sums[:2] / self._sums[2]).tolist()
        self.value = self.ratio * abs(mean_r) / max(abs(mean_c), 1e-8)
        return mean_r, mean_c

    def get_state(self) -> dict:
        return {"value": self.value, "sums": self._sums.tolist()}

    def set_state(self, state: dict) -> None:
        self.value, self._sums = float(state["value"]), torch.tensor(state["sums"])


class FixedBound:
    """A constant upper bound on ν (OmniSafe's ``lagrangian_upper_bound``, FOCOPS's ``nu_max``):
    :class:`AdaptiveBound`'s interface with nothing to observe."""

    def __init__(self, value: float):
        self.value = float(value)

    def start_iteration(self) -> None:
        pass

    def observe(self, y_r: torch.Tensor, y_c: torch.Tensor) -> None:
        pass

    def end_iteration(self) -> None:
        return None

    def get_state(self) -> dict:
        return {"value": self.value}

    def set_state(self, state: dict) -> None:
        self.value = float(state["value"])


class LagrangeMultiplier:
    """ν ≥ 0 of one constrained module: ``value`` is its RLModule's ν buffer (a 0-d tensor) and
    this object its only writer. ``rule`` makes the step, ``bound`` tracks ȳ and, when
    ``bounded``, caps ν at its ν_max; ``bounded=False`` is eq. (14) as [P] writes it."""

    def __init__(self, value: torch.Tensor, *, cost_limit: float, rule: StepRule,
                 bound: AdaptiveBound | FixedBound | None = None,
                 bounded: bool = True):
        self._value, self.cost_limit, self.rule = value, float(cost_limit), rule
        self.bound, self.bounded = bound or AdaptiveBound(), bool(bounded)

    @property
    def value(self) -> float:
        return float(self._value)

    def bind(self, value: torch.Tensor) -> None:
        """Make ``value`` (the module's ν buffer, e.g. after the module was restored) the value."""
        self._value = value

    @property
    def upper(self) -> float | None:
        """The bound ν is held under now (None: unbounded)."""
        return self.bound.value if self.bounded else None

    def step(self, episode_cost: float | None) -> float:
        """One projected step from Ĵ_C = ``episode_cost``; None (no episode completed) leaves ν."""
        if episode_cost is not None:
            nu = max(0.0, self.rule.step(self.value, float(episode_cost), self.cost_limit))
            upper = self.upper
            self._value.fill_(min(nu, upper) if upper is not None else nu)
        return self.value

    def get_state(self) -> dict:
        """The step rule's and the bound's state (ν itself is in the module's weights)."""
        return {"rule": self.rule.get_state(), "bound": self.bound.get_state()}

    def set_state(self, state: dict) -> None:
        self.rule.set_state(state["rule"])
        self.bound.set_state(state["bound"])


class Multipliers:
    """The K multipliers ν_k of a module with K constraints, each its own
    :class:`LagrangeMultiplier` (its rule, its bound, its state) on its entry of the module's (K,)
    ν buffer, stepped on its own constraint's Ĵ_Ck against its own limit b_k: the Lagrangian of K
    constraints, L = J_R − Σ_k ν_k·(J_Ck − b_k), is separable in the ν_k, so each dual step is
    eq. (14) for its constraint alone (Achiam et al. 2017, §6.2, one dual variable per constraint).
    One object with :class:`LagrangeMultiplier`'s interface where the learners use it."""

    def __init__(self, value: torch.Tensor, limits, make, held: int | None = None):
        """``make(value_k, b_k)`` builds constraint k's multiplier on ``value[k]``, a view of the buffer;
        constraint ``held``'s is held where it is instead (``nu_fixed_constraint``)."""
        self.parts = [LagrangeMultiplier(value[k], cost_limit=float(b), rule=HeldStep(), bounded=False) if k == held
                      else make(value[k], float(b)) for k, b in enumerate(limits)]

    @property
    def value(self) -> list[float]:
        return [m.value for m in self.parts]

    def bind(self, value: torch.Tensor) -> None:
        for k, m in enumerate(self.parts):
            m.bind(value[k])

    def step(self, episode_costs) -> list[float]:
        """Each ν_k's projected step on its Ĵ_Ck (``episode_costs``, K numbers; None: no step)."""
        if episode_costs is not None:
            for m, c in zip(self.parts, episode_costs, strict=True):
                m.step(c)
        return self.value

    def get_state(self) -> dict:
        return {"constraints": [m.get_state() for m in self.parts]}

    def set_state(self, state: dict) -> None:
        for m, saved in zip(self.parts, state["constraints"], strict=True):
            m.set_state(saved)


def multipliers_for(value: torch.Tensor, config, make) -> "LagrangeMultiplier | Multipliers":
    """A module's multiplier: ``make(value, b)`` with one constraint, :class:`Multipliers` of
    ``make(value[k], b_k)`` with K (the limits of ``config.constraint_set``)."""
    several = getattr(config, "constraint_set", None)  # a config without constraints: one
    if several is None or len(several) == 1:
        return make(value, config.effective_cost_limit)
    held = getattr(config, "nu_fixed_constraint", None) if getattr(config, "nu_fixed", None) is not None else None
    # The frontier along one constraint: its ν_k held at nu_fixed, the others learning.
    return Multipliers(value, several.limits, make, held=None if held is None else several.names.index(held))


def each_multiplier(multiplier) -> list:
    """The :class:`LagrangeMultiplier` of each constraint: ``[multiplier]`` with one, its parts with K."""
    return multiplier.parts if isinstance(multiplier, Multipliers) else [multiplier]


def nu_weighted(nu: torch.Tensor, cost: torch.Tensor) -> torch.Tensor:
    """ν·x with one constraint (ν 0-d); Σ_k ν_k·x_k with K (ν (K,), x (..., K))."""
    return nu * cost if nu.dim() == 0 else cost @ nu


def nu_total(nu: torch.Tensor) -> torch.Tensor:
    """ν, or Σ_k ν_k with K constraints (the 1 + Σν that normalises a Lagrangian advantage)."""
    return nu if nu.dim() == 0 else nu.sum()


def restore_multipliers(multipliers: dict, modules, saved: dict) -> None:
    """After a learner's ``set_state``: each module's multiplier bound again to the module's ν
    buffer (RLlib's restore replaced the module's tensors), then its rule's state from ``saved``
    (module id → ``LagrangeMultiplier.get_state()``; modules missing from it keep theirs)."""
    for mid, module in modules.items():
        multipliers[mid].bind(module.unwrapped().nu)
    for mid, state in saved.items():
        multipliers[mid].set_state(state)


def fixed_multiplier(value: torch.Tensor, config) -> "LagrangeMultiplier | Multipliers | None":
    """The multiplier of a run whose config sets ``nu_fixed`` (ν held at it, unbounded; each ν_k with
    several constraints); None where ν learns (the algorithm's own rule then)."""
    if getattr(config, "nu_fixed", None) is None or getattr(config, "nu_fixed_constraint", None) is not None:
        return None  # learns (with nu_fixed_constraint: the one it names held by multipliers_for)
    return multipliers_for(value, config, lambda v, b: LagrangeMultiplier(v, cost_limit=b, rule=HeldStep(),
                                                                           bounded=False))
