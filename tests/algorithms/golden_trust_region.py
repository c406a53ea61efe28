"""Golden steps of the trust-region family (TRPO-Lag, CPO, PCPO; fixtures recorded by
benchmarks/golden/omnisafe_trust_region.py): the project's learner takes the recorded step, the
whole batch's trust-region step at the update's first loss call (then, TRPO-Lag only compared, one
critic minibatch on the same batch), and :func:`trust_region_step` returns what OmniSafe recorded
under its names. What the step computes on the way (the solves x = H⁻¹g and p = H⁻¹b, the full
step, the dual's scalars, the line search's outcome) is read by wrapping the functions the
learners call, as the recording wraps OmniSafe's; vectors are put in OmniSafe's parameter order."""

from __future__ import annotations

import math
from unittest import mock

import numpy as np
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, VF_LOSS_KEY

from lac_rllib.algorithms.cpo import learner as cpo_learner
from lac_rllib.algorithms.pcpo import learner as pcpo_learner
from lac_rllib.constrained.metrics import COST_VF_LOSS, TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.families.trust_region import learner as trpo_learner
from tests.algorithms.golden import OMNISAFE_ON_POLICY, Fixture, build_on_policy, minibatch_step, on_policy_batch, ours

REVERSE = {v: k for k, v in OMNISAFE_ON_POLICY.items()}
OMNISAFE_EPS = 1e-8  # [O trpo.py:192, cpo.py:286]: α = √(2δ/(xHx + 1e-8))


class Seen:
    """What the learner's step computed, caught on its way through the functions it calls."""

    def __init__(self):
        self.solves, self.searches, self.steps, self.q = [], [], [], None

    def patches(self, learner) -> list:
        """The wrappers, as ``mock.patch`` objects to start and stop."""
        originals = {"trpo_step": trpo_learner.trpo_step, "cpo_step": cpo_learner.cpo_step,
                     "pcpo_step": pcpo_learner.pcpo_step, "search": learner.search}

        def solve(original):
            return lambda *a, **k: self._kept(self.solves, original(*a, **k))

        def trpo_step(x, q, max_kl):
            self.q = float(q)
            return originals["trpo_step"](x, q, max_kl)

        def search(policy, step, accept, config, loss):
            out = originals["search"](policy, step, accept, config, loss)
            self.searches.append((step.detach().clone(), out[0]))
            return out

        return [mock.patch.object(trpo_learner, "conjugate_gradient", solve(trpo_learner.conjugate_gradient)),
                mock.patch.object(cpo_learner, "conjugate_gradient", solve(cpo_learner.conjugate_gradient)),
                mock.patch.object(trpo_learner, "trpo_step", trpo_step),
                mock.patch.object(cpo_learner, "cpo_step",
                                  lambda *a, **k: self._kept(self.steps, originals["cpo_step"](*a, **k))),
                mock.patch.object(pcpo_learner, "pcpo_step",
                                  lambda *a, **k: self._kept(self.steps, originals["pcpo_step"](*a, **k))),
                mock.patch.object(learner, "search", search)]

    @staticmethod
    def _kept(store: list, value):
        store.append(value.detach().clone() if isinstance(value, torch.Tensor) else value)
        return value


def reference_order(flat: torch.Tensor, policy_params, module, fx: Fixture) -> np.ndarray:
    """A flat vector over the learner's policy parameters in OmniSafe's order (its actor's
    ``named_parameters``: the fixture's ``before/actor.*`` order)."""
    names = {id(p): n for n, p in module.named_parameters()}
    pieces, offset = {}, 0
    for p in policy_params:
        pieces[ours(names[id(p)], REVERSE)] = flat[offset:offset + p.numel()]
        offset += p.numel()
    return torch.cat([pieces[k].reshape(-1) for k in fx.before if k.startswith("actor.")]).numpy()


def trust_region_step(config_cls, fx: Fixture, scenario: str = "", preset=None, **fields) -> dict:
    """The fixture's step (``scenario``'s, for a fixture recording several) taken by the project's
    learner; its outputs under the fixture's names (benchmarks/golden/omnisafe_trust_region.py)."""
    learner = build_on_policy(config_cls, fx, preset, **fields)
    mid = DEFAULT_MODULE_ID
    module, config = learner.module[mid].unwrapped(), learner.config.get_config_for_module(mid)
    prefix = f"{scenario}/" if scenario else ""
    l2 = {net: config.critic_l2 * sum(float((p.detach() ** 2).sum()) for n, p in module.named_parameters()
                                      if ours(n, REVERSE).startswith(net)) for net in ("reward_critic", "cost_critic")}
    out = {}
    learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [float(fx.inputs[f"{prefix}ep_cost"])]})
    if "nu" in fx.outputs:  # float32 on both sides: compared, then the reference's (golden.multiplier_step)
        out["nu"] = float(module.nu)
        module.nu.fill_(float(fx.outputs["nu"]))
    batch = on_policy_batch(fx)
    learner.cost_gae.last_batch = {mid: batch}  # the whole batch its learner connector would keep
    seen = Seen()
    policy = trpo_learner.PolicyOnBatch(module, batch, config.kl_convention)
    patches = seen.patches(learner)
    for patch in patches:
        patch.start()
    try:
        grads = minibatch_step(learner, batch)
    finally:
        for patch in reversed(patches):
            patch.stop()
    vector = lambda v: reference_order(v, policy.params, module, fx)  # noqa: E731
    (step_direction, result), = seen.searches
    max_kl = policy.max_kl(config)
    out.update({"x": vector(seen.solves[0]), "step_direction": vector(step_direction),
                "acceptance_step": result.backtracks + 1 if result.accepted else 0})
    if seen.steps:  # CPO, PCPO
        cpo, = seen.steps
        out.update({"p": vector(seen.solves[1]), "q": cpo.q, "r": cpo.r, "s": cpo.s})
        if hasattr(cpo, "case"):
            out.update({"A": cpo.A, "B": cpo.B, "optim_case": cpo.case, "lambda_star": cpo.lam, "nu_star": cpo.nu})
        seen.q = cpo.q
    out.update({"xHx": seen.q, "alpha": math.sqrt(2 * max_kl / (seen.q + OMNISAFE_EPS))})
    if result.accepted:
        out["kl"] = learner.progress[mid].kl
    peek = lambda key: float(torch.as_tensor(learner.metrics.peek((mid, key))).detach())  # noqa: E731
    if seen.steps:  # [O cpo.py:438-441]: the reward's loss plus the cost surrogate, after the step
        with torch.no_grad():
            out["loss_pi"] = peek(POLICY_LOSS_KEY) + float(policy.surrogate(batch[COST_ADVANTAGES]))
    else:
        out["loss_pi"] = peek(POLICY_LOSS_KEY)
        out.update({"loss_reward_critic": peek(VF_LOSS_KEY) + l2["reward_critic"],
                    "loss_cost_critic": peek(COST_VF_LOSS) + l2["cost_critic"]})
        out.update({f"grad/{ours(n, REVERSE)}": g.numpy() for n, g in grads.items()})
    out.update({f"after/{ours(n, REVERSE)}": p.detach().numpy() for n, p in module.named_parameters()})
    return {k if k in ("x", "p") else f"{prefix}{k}": v for k, v in out.items()}  # the solves: not per scenario


def scenario_outputs(fx: Fixture, scenario: str = "") -> dict:
    """The recorded outputs of one of the fixture's steps (all of them for a fixture of one)."""
    return {k: v for k, v in fx.outputs.items() if not scenario or k.startswith(f"{scenario}/") or k in ("x", "p")}
