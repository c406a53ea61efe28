"""Record OmniSafe 0.5.0's own update step of PPO-Lag, FOCOPS, CUP and P3O on one seeded batch.

Run with OmniSafe's venv (benchmarks/golden/omnisafe_venv.sh; docs/golden.md), from the repository root:

    OMNISAFE_PY benchmarks/golden/omnisafe_first_order.py --algos ppo_lag,focops,cup,p3o

Each algorithm's object is built by ``omnisafe.Agent`` on SafetyPointGoal1-v0 (obs 60, act 2) with
(16, 16) networks (small fixtures; the step's arithmetic does not depend on the width), turned to
float64; then its own methods take one step, as its ``_update`` calls them for one minibatch:
the multiplier's ``update_lagrange_multiplier(Jc)`` (Jc = EpCost, read where the reference reads it:
its logger's ``get_stats``), ``_update_reward_critic``, ``_update_cost_critic``, ``_update_actor``
(FOCOPS with ``_p_dist``, the policy at the update's start, set to the batch's behaviour policy, as
its ``_update`` does per minibatch); CUP then its second stage's step (``_loss_pi_cost`` on
``_p_dist``, the clip and Adam step of its ``_update``). The behaviour policy is the starting policy
moved by noise, so ratios leave the clip range and some rows leave FOCOPS's and CUP's trust region.
PPO-Lag's fixture also records where the step's advantages come from: OmniSafe's own buffer, fed a
rollout over the batch's observations (three episode chunks: terminated, cut by a time limit, cut
by the epoch's end), its GAE per chunk and its ``get``, which standardises A^R and centres A^C.
Written to tests/fixtures/golden/<algo>-omnisafe.npz (benchmarks/golden/fixture.py)."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402  (the format, shared with the tests' loader)

OMNISAFE_NAMES = {"ppo_lag": "PPOLag", "focops": "FOCOPS", "cup": "CUP", "p3o": "P3O"}
ROWS, HIDDEN, EP_COST, SEED = 64, [16, 16], 40.0, 0
#: The fixtures that also record OmniSafe's buffer on a rollout over the batch's observations.
BUFFER_ALGOS = ("ppo_lag",)
#: That rollout's episode chunks over the batch's rows, in order: (rows, how the chunk ends).
CHUNKS = ((20, "terminated"), (25, "time_limit"), (19, "epoch_end"))


def build(algo: str):
    import omnisafe

    cfgs = {"seed": SEED, "train_cfgs": {"total_steps": 2000, "vector_env_nums": 1, "parallel": 1,
                                         "torch_threads": 1, "device": "cpu"},
            "algo_cfgs": {"steps_per_epoch": 1000},
            "logger_cfgs": {"use_wandb": False, "use_tensorboard": False, "log_dir": tempfile.mkdtemp()},
            "model_cfgs": {"actor": {"hidden_sizes": HIDDEN}, "critic": {"hidden_sizes": HIDDEN}}}
    agent = omnisafe.Agent(OMNISAFE_NAMES[algo], "SafetyPointGoal1-v0", custom_cfgs=cfgs).agent
    agent._actor_critic.double()  # noqa: SLF001  parameters keep their identity: the optimizers stay valid
    return agent


class Recorder:
    """What the reference logs (its ``logger.store``) and each optimizer's gradients at its step
    (after the clip: what Adam consumes), keyed by the actor-critic's parameter names."""

    def __init__(self, agent):
        self.logged, self.grads = {}, {}
        ac = agent._actor_critic  # noqa: SLF001
        names = {id(p): n for n, p in ac.named_parameters()}
        agent._logger.store = lambda data, **_: self.logged.update(  # noqa: SLF001
            {k: float(v.mean()) if torch.is_tensor(v) else float(v) for k, v in data.items()})
        for optim in (ac.actor_optimizer, ac.reward_critic_optimizer, ac.cost_critic_optimizer):
            self._wrap(optim, names)

    def _wrap(self, optim, names):
        step = optim.step

        def recording_step(*args, **kwargs):
            for group in optim.param_groups:
                for p in group["params"]:
                    key = names[id(p)]
                    self.grads[key if key not in self.grads else f"{key}#2"] = p.grad.detach().clone()
            return step(*args, **kwargs)

        optim.step = recording_step


def make_batch(agent, rng: np.random.Generator) -> dict:
    """Observations N(0, 1); actions from a behaviour policy = the starting policy with its mean
    moved by N(0, 0.15²) and log σ by N(0, 0.1²) per row; logp the behaviour policy's; advantages
    and value targets N(0, 1) (targets offset from the critics' outputs)."""
    obs_dim = agent._env.observation_space.shape[0]  # noqa: SLF001
    act_dim = agent._env.action_space.shape[0]  # noqa: SLF001
    obs = torch.as_tensor(rng.normal(size=(ROWS, obs_dim)))
    with torch.no_grad():
        dist = agent._actor_critic.actor(obs)  # noqa: SLF001
        old_mean = dist.mean + torch.as_tensor(rng.normal(scale=0.15, size=(ROWS, act_dim)))
        old_log_std = dist.stddev.log() + torch.as_tensor(rng.normal(scale=0.1, size=(ROWS, act_dim)))
        behaviour = Normal(old_mean, old_log_std.exp())
        act = behaviour.mean + behaviour.stddev * torch.as_tensor(rng.normal(size=(ROWS, act_dim)))
        logp = behaviour.log_prob(act).sum(-1)
    return {"obs": obs, "act": act, "logp": logp, "old_mean": old_mean, "old_log_std": old_log_std,
            "adv_r": torch.as_tensor(rng.normal(size=ROWS)), "adv_c": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_r": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_c": torch.as_tensor(rng.normal(loc=2.0, size=ROWS))}


def make_rollout(agent, rng: np.random.Generator) -> dict:
    """Rewards N(0.5, 2²) (the raw advantages' mean and spread then far from 0 and 1), costs 1 with
    probability 0.3, and the observation after each chunk's last row, N(0, 1)."""
    obs_dim = agent._env.observation_space.shape[0]  # noqa: SLF001
    return {"rollout/reward": torch.as_tensor(rng.normal(0.5, 2.0, size=ROWS)),
            "rollout/cost": torch.as_tensor((rng.random(ROWS) < 0.3).astype(np.float64)),
            "rollout/last_obs": torch.as_tensor(rng.normal(size=(len(CHUNKS), obs_dim)))}


def buffer_step(agent, batch: dict, rollout: dict) -> dict:
    """OmniSafe's own ``VectorOnPolicyBuffer``, built as ``PolicyGradient._init`` builds it
    [O policy_gradient.py:118-131] but sized to the batch, and fed as ``OnPolicyAdapter.rollout``
    feeds it [O onpolicy_adapter.py:85-131]: each row stored with the critics' values at its
    observation (``ConstraintActorCritic.step``'s value_r, value_c [O constraint_actor_critic.py:103-109]),
    each chunk finished with 0 if it terminated, else with the critics' values at the observation
    after it (a time limit's final observation, the epoch's last); then its ``get`` (A^R standardised
    with the population std, A^C centred [O vector_onpolicy_buffer.py:131-136]). The values are
    handed over in float32, as OmniSafe's own (float32) critics hand them: a float64 last value
    would promote ``finish_path``'s concatenated rewards to float64, and its ``discount_cumsum``,
    whose ``.type(torch.float64)`` is then no copy, would overwrite them with the discounted
    returns before the GAE reads them [O onpolicy_buffer.py:finish_path, utils/math.py:77-82].
    Returns its outputs (``buffer/*``) and, for the meta, the mean and std of A^R and A^C before
    ``get`` standardised them."""
    from omnisafe.common.buffer import VectorOnPolicyBuffer

    algo_cfgs, ac = agent._cfgs.algo_cfgs, agent._actor_critic  # noqa: SLF001
    buf = VectorOnPolicyBuffer(
        obs_space=agent._env.observation_space, act_space=agent._env.action_space,  # noqa: SLF001
        size=ROWS, gamma=algo_cfgs.gamma, lam=algo_cfgs.lam, lam_c=algo_cfgs.lam_c,
        advantage_estimator=algo_cfgs.adv_estimation_method, standardized_adv_r=algo_cfgs.standardized_rew_adv,
        standardized_adv_c=algo_cfgs.standardized_cost_adv, penalty_coefficient=algo_cfgs.penalty_coef, num_envs=1)
    values = lambda obs: (ac.reward_critic(obs)[0].float(), ac.cost_critic(obs)[0].float())  # noqa: E731
    start = 0
    with torch.no_grad():
        for k, (rows, end) in enumerate(CHUNKS):
            for t in range(start, start + rows):
                value_r, value_c = values(batch["obs"][t])
                buf.store(obs=batch["obs"][t][None], act=batch["act"][t][None],
                          reward=rollout["rollout/reward"][t][None], cost=rollout["rollout/cost"][t][None],
                          value_r=value_r[None], value_c=value_c[None], logp=batch["logp"][t][None])
            if end == "terminated":
                last_r, last_c = torch.zeros(1), torch.zeros(1)
            else:
                last_r, last_c = (v[None] for v in values(rollout["rollout/last_obs"][k]))
            buf.finish_path(last_r, last_c, 0)
            start += rows
        raw = {k: buf.buffers[0].data[k].clone() for k in ("adv_r", "adv_c")}  # before get's standardisation
        data = buf.get()
    out = {f"buffer/{k}": data[k] for k in ("adv_r", "adv_c", "target_value_r", "target_value_c")}
    return out, {f"raw_{k}": {"mean": float(v.mean()), "std": float(v.std(unbiased=False))} for k, v in raw.items()}


def step(algo: str, agent, batch: dict, ep_cost: float) -> dict:
    """The reference's own methods, in its ``_update``'s order for one minibatch."""
    ac, cfgs = agent._actor_critic, agent._cfgs  # noqa: SLF001
    agent._logger.get_stats = lambda key, *_: (ep_cost, 0.0, 0.0, 0.0) if key == "Metrics/EpCost" else None  # noqa: SLF001
    rec = Recorder(agent)
    out = {}
    if hasattr(agent, "_lagrange"):
        agent._lagrange.update_lagrange_multiplier(ep_cost)  # noqa: SLF001
        out["nu"] = float(agent._lagrange.lagrangian_multiplier)  # noqa: SLF001
    b = batch
    agent._update_reward_critic(b["obs"], b["target_value_r"])  # noqa: SLF001
    agent._update_cost_critic(b["obs"], b["target_value_c"])  # noqa: SLF001
    if algo == "focops":
        agent._p_dist = Normal(b["old_mean"], b["old_log_std"].exp())  # noqa: SLF001
    agent._update_actor(b["obs"], b["act"], b["logp"], b["adv_r"], b["adv_c"])  # noqa: SLF001
    out.update({"loss_pi": rec.logged["Loss/Loss_pi"], "loss_reward_critic": rec.logged["Loss/Loss_reward_critic"],
                "loss_cost_critic": rec.logged["Loss/Loss_cost_critic"]})
    if algo == "p3o":
        out["loss_pi_cost"] = rec.logged["Loss/Loss_pi_cost"]
    out.update({f"grad/{k}": v for k, v in rec.grads.items()})
    out.update({f"after/{k}": v.detach().clone() for k, v in ac.state_dict().items()})
    if algo == "cup":  # the second stage, one minibatch: its _update's loop body
        agent._p_dist = Normal(b["old_mean"], b["old_log_std"].exp())  # noqa: SLF001
        rec.grads.clear()
        loss_cost = agent._loss_pi_cost(b["obs"], b["act"], b["logp"], b["adv_c"])  # noqa: SLF001
        ac.actor_optimizer.zero_grad()
        loss_cost.backward()
        if cfgs.algo_cfgs.max_grad_norm is not None:
            torch.nn.utils.clip_grad_norm_(ac.actor.parameters(), cfgs.algo_cfgs.max_grad_norm)
        ac.actor_optimizer.step()
        out["stage2/loss_pi_c"] = rec.logged["Loss/Loss_pi_c"]
        out.update({f"stage2/grad/{k}": v for k, v in rec.grads.items()})
        out.update({f"stage2/after/{k}": v.detach().clone() for k, v in ac.actor.state_dict().items()})
    return out


def record(algo: str, out_dir: Path) -> Path:
    import omnisafe

    torch.manual_seed(SEED)
    agent = build(algo)
    before = {k: v.detach().clone() for k, v in agent._actor_critic.state_dict().items()}  # noqa: SLF001
    batch = make_batch(agent, np.random.default_rng(SEED))
    rollout = make_rollout(agent, np.random.default_rng(SEED + 1)) if algo in BUFFER_ALGOS else {}
    buffered, raw = buffer_step(agent, batch, rollout) if rollout else ({}, {})  # the critics before the step
    outputs = {**step(algo, agent, batch, EP_COST), **buffered}
    cfgs = agent._cfgs  # noqa: SLF001
    meta = {"reference": "OmniSafe", "reference_version": omnisafe.__version__,
            "reference_source": "PyPI omnisafe==0.5.0 (its installed algorithms/on_policy/*.py)",
            "algorithm": algo, "omnisafe_class": OMNISAFE_NAMES[algo], "task": "SafetyPointGoal1-v0",
            "hidden": HIDDEN, "rows": ROWS, "torch": torch.__version__,
            "command": "OMNISAFE_PY benchmarks/golden/omnisafe_first_order.py --algos " + algo,
            "algo_cfgs": {k: v for k, v in cfgs.algo_cfgs.todict().items() if not isinstance(v, dict)},
            "lagrange_cfgs": cfgs.lagrange_cfgs.todict() if "lagrange_cfgs" in cfgs else None,
            "lr": cfgs.model_cfgs.actor.lr, "critic_lr": cfgs.model_cfgs.critic.lr,
            **({"rollout_chunks": [list(c) for c in CHUNKS], "rollout_advantages": raw} if rollout else {})}
    inputs = {**batch, **rollout, "ep_cost": EP_COST}
    if "nu" in outputs:
        inputs["nu_before"] = float(cfgs.lagrange_cfgs.lagrangian_multiplier_init)
    return fixture.save(out_dir / f"{algo}-omnisafe.npz", meta, inputs, before, outputs)


def main() -> None:
    fixture.run_for_algos(__doc__, OMNISAFE_NAMES, record)


if __name__ == "__main__":
    main()
