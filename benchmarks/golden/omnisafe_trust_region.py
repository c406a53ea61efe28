"""Record OmniSafe 0.5.0's own trust-region step of TRPO-Lag, CPO and PCPO on one seeded batch.

Run with OmniSafe 0.5.0's own venv (``benchmarks/golden/omnisafe_venv.sh DIR`` builds one; OMNISAFE_PY is
DIR/bin/python), from the repository root:

    OMNISAFE_PY benchmarks/golden/omnisafe_trust_region.py --algos trpo_lag,cpo,pcpo

Built as omnisafe_first_order.py builds (``omnisafe.Agent`` on SafetyPointGoal1-v0, (16, 16)
networks, float64, its batch recipe) on 128 rows, then the algorithm's own ``_update_actor(obs,
act, logp, adv_r, adv_c)`` on the whole batch, as its ``_update`` calls it [O natural_pg.py:207]:
TRPO-Lag after its multiplier's ``update_lagrange_multiplier(Jc)`` [O trpo_lag.py:63-66] and
followed by one critic minibatch (``_update_reward_critic``, ``_update_cost_critic`` on the whole
batch, [O natural_pg.py:215-223]); CPO and PCPO read Jc − cost_limit from the logger's
``get_stats('Metrics/EpCost')`` [O cpo.py:391, pcpo.py:554], fed here.

What the step computes is read from the reference's own calls: the conjugate-gradient solves (x =
H⁻¹g, and CPO's and PCPO's p = H⁻¹b) by wrapping the ``conjugate_gradients`` its module calls, the
full step and the line search's result by wrapping ``_search_step_size`` / ``_cpo_search_step``,
the scalars (xHx, α, CPO's q, r, s, A, B, λ*, ν*, case, ``AcceptanceStep``, ``Train/KL``) from its
``logger.store``; then the parameters after. CPO is recorded four times on the same weights and
batch, Jc chosen so that the three cases of its dual and recovery arise and its line search backs
off: ``case2`` (Jc 24.95: c < 0, the boundary cuts the trust region; [O]'s dual gives λ* < 0 and
the line search rejects all 20 fractions), ``case1`` (Jc 25.09: θ_old infeasible, a feasible part
in reach; ν* > 0), ``case0`` (Jc 40: recovery along −H⁻¹b) and ``backtrack`` (Jc 25.051: case 1
again, its step's linear cost change just below 0, so that the surrogate's curvature makes the
cost rise at the full step and at the next six fractions, by 2.1e-3 down to 4.6e-5, and the line
search accepts the 8th, 0.8⁷). PCPO's Jc 26 makes its projection bind and its line search back off
8 times. Written to tests/fixtures/golden/<algo>-omnisafe.npz (benchmarks/golden/fixture.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402  (the format, shared with the tests' loader)
import omnisafe_first_order as first_order  # noqa: E402  (build, Recorder, make_batch)

OMNISAFE_NAMES = {"trpo_lag": "TRPOLag", "cpo": "CPO", "pcpo": "PCPO"}
#: The module whose ``conjugate_gradients`` each class's ``_update_actor`` calls, and its line search.
SOLVER_MODULE = {"trpo_lag": "omnisafe.algorithms.on_policy.base.trpo",
                 "cpo": "omnisafe.algorithms.on_policy.second_order.cpo",
                 "pcpo": "omnisafe.algorithms.on_policy.second_order.pcpo"}
SEARCH = {"trpo_lag": "_search_step_size", "cpo": "_cpo_search_step", "pcpo": "_cpo_search_step"}
#: Jc per recorded step (scenario name → the episode cost the step reads).
EP_COSTS = {"trpo_lag": {"": 40.0}, "cpo": {"case2": 24.95, "case1": 25.09, "case0": 40.0, "backtrack": 25.051},
            "pcpo": {"": 26.0}}
ROWS = 128
first_order.OMNISAFE_NAMES.update(OMNISAFE_NAMES)  # first_order.build looks the class up there
first_order.ROWS = ROWS  # first_order.make_batch's rows
#: What [O] logs, under the fixture's names (CPO's and PCPO's ``_update_actor`` store the rest).
LOGGED = {"Misc/xHx": "xHx", "Misc/Alpha": "alpha", "Misc/AcceptanceStep": "acceptance_step", "Loss/Loss_pi": "loss_pi"}
CPO_LOGGED = {"Misc/q": "q", "Misc/r": "r", "Misc/s": "s", "Misc/A": "A", "Misc/B": "B", "Misc/OptimCase": "optim_case",
              "Misc/Lambda_star": "lambda_star", "Misc/Nu_star": "nu_star"}


class Recorder(first_order.Recorder):
    """first_order's, but the trust-region actor-critic has no actor optimizer (the critics' only),
    plus what the step's solver and line search return."""

    def __init__(self, agent, algo: str):
        self.logged, self.grads, self.solves, self.searches = {}, {}, [], []
        ac = agent._actor_critic  # noqa: SLF001
        names = {id(p): n for n, p in ac.named_parameters()}
        agent._logger.store = lambda data, **_: self.logged.update(  # noqa: SLF001
            {k: float(v.detach().mean()) if torch.is_tensor(v) else float(v) for k, v in data.items()})
        agent._logger.log = lambda *_, **__: None  # noqa: SLF001  (its line search's chatter)
        for optim in (ac.reward_critic_optimizer, ac.cost_critic_optimizer):
            self._wrap(optim, names)
        self.module = sys.modules[SOLVER_MODULE[algo]]
        self.solve = solve = self.module.conjugate_gradients
        self.module.conjugate_gradients = lambda *a, **k: self._kept(self.solves, solve(*a, **k))
        search = getattr(agent, SEARCH[algo])

        def recording_search(**kwargs):
            step, accepted = search(**kwargs)
            self.searches.append((kwargs["step_direction"].detach().clone(), step.detach().clone(), accepted))
            return step, accepted

        setattr(agent, SEARCH[algo], recording_search)

    def close(self) -> None:
        self.module.conjugate_gradients = self.solve

    @staticmethod
    def _kept(store: list, value):
        store.append(value.detach().clone())
        return value


def step(algo: str, agent, batch: dict, ep_cost: float) -> dict:
    """The reference's own calls, in its ``_update``'s order (module docstring)."""
    ac = agent._actor_critic  # noqa: SLF001
    agent._logger.get_stats = lambda key, *_: (ep_cost, 0.0, 0.0, 0.0) if key == "Metrics/EpCost" else None  # noqa: SLF001
    rec = Recorder(agent, algo)
    out, b = {}, batch
    if hasattr(agent, "_lagrange"):
        agent._lagrange.update_lagrange_multiplier(ep_cost)  # noqa: SLF001
        out["nu"] = agent._lagrange.lagrangian_multiplier.item()  # noqa: SLF001
    agent._update_actor(b["obs"], b["act"], b["logp"], b["adv_r"], b["adv_c"])  # noqa: SLF001
    rec.close()
    (step_direction, _, _), = rec.searches
    out.update({"x": rec.solves[0], "step_direction": step_direction})
    if algo != "trpo_lag":
        out["p"] = rec.solves[1]
    logged = {**LOGGED, **(CPO_LOGGED if algo == "cpo" else {}), **({"Misc/q": "q", "Misc/r": "r", "Misc/s": "s"}
                                                                     if algo == "pcpo" else {})}
    out.update({name: rec.logged[key] for key, name in logged.items()})
    if out["acceptance_step"] > 0:  # the KL at the accepted point ([O] logs the last one tried)
        out["kl"] = rec.logged["Train/KL"]
    out.update({f"after/{k}": v.detach().clone() for k, v in ac.state_dict().items() if k.startswith("actor.")})
    if algo == "trpo_lag":  # one critic minibatch after the actor's step: the whole batch
        agent._update_reward_critic(b["obs"], b["target_value_r"])  # noqa: SLF001
        agent._update_cost_critic(b["obs"], b["target_value_c"])  # noqa: SLF001
        out.update({"loss_reward_critic": rec.logged["Loss/Loss_reward_critic"],
                    "loss_cost_critic": rec.logged["Loss/Loss_cost_critic"]})
        out.update({f"grad/{k}": v for k, v in rec.grads.items()})
        out.update({f"after/{k}": v.detach().clone() for k, v in ac.state_dict().items() if "critic" in k})
    return out


def record(algo: str, out_dir: Path) -> Path:
    import omnisafe

    inputs, outputs, before = {}, {}, None
    for scenario, ep_cost in EP_COSTS[algo].items():
        torch.manual_seed(first_order.SEED)
        agent = first_order.build(algo)  # the same weights each time (seeded)
        state = {k: v.detach().clone() for k, v in agent._actor_critic.state_dict().items()}  # noqa: SLF001
        assert before is None or all(torch.equal(state[k], before[k]) for k in state)
        before = state
        batch = first_order.make_batch(agent, np.random.default_rng(first_order.SEED))
        prefix = f"{scenario}/" if scenario else ""
        inputs.update({**batch, f"{prefix}ep_cost": ep_cost})
        got = step(algo, agent, batch, ep_cost)
        for shared in ("x", "p"):  # the solves do not read Jc: kept once
            if shared in got:
                value = got.pop(shared)
                assert shared not in outputs or torch.equal(outputs[shared], value)
                outputs[shared] = value
        outputs.update({f"{prefix}{k}": v for k, v in got.items()})
    cfgs = agent._cfgs  # noqa: SLF001
    meta = {"reference": "OmniSafe", "reference_version": omnisafe.__version__,
            "reference_source": "PyPI omnisafe==0.5.0 (its installed algorithms/on_policy/*.py)",
            "algorithm": algo, "omnisafe_class": OMNISAFE_NAMES[algo], "task": "SafetyPointGoal1-v0",
            "hidden": first_order.HIDDEN, "rows": ROWS, "torch": torch.__version__,
            "scenarios": {k or "step": v for k, v in EP_COSTS[algo].items()},
            "command": "OMNISAFE_PY benchmarks/golden/omnisafe_trust_region.py --algos " + algo,
            "algo_cfgs": {k: v for k, v in cfgs.algo_cfgs.todict().items() if not isinstance(v, dict)},
            "lagrange_cfgs": cfgs.lagrange_cfgs.todict() if "lagrange_cfgs" in cfgs else None,
            "critic_lr": cfgs.model_cfgs.critic.lr}
    if "nu" in outputs:
        inputs["nu_before"] = float(cfgs.lagrange_cfgs.lagrangian_multiplier_init)
    return fixture.save(out_dir / f"{algo}-omnisafe.npz", meta, inputs, before, outputs)


def main() -> None:
    fixture.run_for_algos(__doc__, OMNISAFE_NAMES, record)


if __name__ == "__main__":
    main()
