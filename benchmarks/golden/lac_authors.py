"""Record one LAC update by the authors' own code (github.com/Lfh404/LAC) on one seeded batch.

Run from the repository root with a venv holding torch and numpy (their update needs nothing else;
tests/fixtures/golden/README.md), their code checked out outside this repository:

    git clone <Lfh404/LAC> ~/ref/LAC
    REF_PY benchmarks/golden/lac_authors.py --ref ~/ref/LAC

Their ``main.py`` imports wandb, gym and safety_gym at module level for training; the update does
not touch them, so they are empty stand-ins here and no environment is built. Their own objects
take the step: ``GaussianPolicy`` (actor, (16, 16) tanh), ``Critic`` (twin reward and cost critics,
3×16 Mish; hidden_dim is its constructor's argument), ``LangevinPolicy`` built the way ``train()``
builds it (main.py:267-277, ``args.eta`` landing positionally in ``action_scaling``, so the energy's
weight on log π stays 1), targets as ``train()``'s deep copies, moved by noise as training moves
them, Adam at the learning rate of iteration 1 (``train()``'s LambdaLR, main.py:296, after one step,
3e-4·(1 − 0.5/125)), and ``LAC.update_params(iter=1, rollout, float64)`` (main.py:101-244): ν's
projected step, then per minibatch the chain at s' from π_φ'(·|s'), the reward then the cost
critic's step, the actor's maximum-likelihood step (clip 40) and Polyak of all three targets; at
the end the next bound ν_max. [C]'s hyperparameters are argparse defaults (main.py:397-469):
λ = 1e-4, T = 30, η = 1e-4, chain clip 1000, γ = γ_C = 0.99, τ = 0.005, α_ν = 0.01, b = 25.

What is fixed from outside, without changing their arithmetic:
- the noise: ``torch.normal`` returns recorded draws, z₀ for the chain's start (``get_act``'s
  ``torch.normal(mean, std)`` is mean + std·z₀ by definition) and z₁..z_T for its steps;
- the minibatch order: their DataLoader shuffles; here it does not (the rows of each minibatch
  are then the buffer's in order, which the fixture records);
- float64: their ``dtype`` argument and torch's default dtype.
Also recorded (by wrapping, not changing, what they call): the critics' targets and losses (the
second argument and the value of each ``F.mse_loss``), the chain's end points
(``LangevinPolicy.forward``'s result), log π_φ(ã|s') of the actor loss, the gradients each
optimizer stepped on (after the actor's clip), and the norms their ``clip_grad_norm_`` saw (in
meta: whether each clip bound).
The update is recorded twice from the same weights and noise: as [C] trains (gym 0.21's ``done``
stored in ``terminals``: a time-limit truncation ends the target's bootstrap) and, under
``bootstrap/``, with only the terminated rows in ``terminals``, as [C]'s update reads a buffer of a
gymnasium env whose truncations are not terminal: its targets then bootstrap past a truncation,
as the project's default (``bootstrap_on_truncation=True``) does.
Written to tests/fixtures/golden/lac-authors.npz (benchmarks/golden/fixture.py)."""

from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402  (the format, shared with the tests' loader)

ROOT = Path(__file__).resolve().parents[2]
OBS, ACT, ROWS, MB, HIDDEN, SEED = 60, 2, 64, 32, 16, 0  # SafetyPointGoal1's dims; two minibatches
# [C]'s argparse defaults (main.py:397-469); the README's command passes none of these.
C = dict(gamma=0.99, c_gamma=0.99, tau=0.005, lam=1e-4, nu_lr=0.01, nu_max_factor=2.0, cost_lim=25.0,
         langevin_steps=30, langevin_stepsize=1e-4, act_grad_norm=1000.0, actor_grad_norm=40.0,
         reward_grad_norm=0.0, cost_grad_norm=0.0, reward_scaling=10.0, eta=1.0, logstd=-0.5,
         actor_lr=3e-4, critic_lr=3e-4, max_iter_num=125, l2_reg=1e-3, policy_freq=1, num_epochs=1)
ITERATION, BATCH_STEPS = 1, 20_000       # the update of iteration 1 (the first that trains the actor)
LR = C["actor_lr"] * max(1.0 - 0.5 * ITERATION / C["max_iter_num"], 0.0)  # train()'s LambdaLR, one step
# The critics' output layers ×3: steeper in a than at init, as trained critics are, so that the
# chain's batch clip (1000) binds at some of its steps and not at others (meta: which).
CRITIC_SLOPE = 3.0
NU0, NU_MAX0, EP_COST = 1.0, 2.0, 37.5   # ν 1 → 1.125, inside the bound (exact in float32 too)


def import_reference(ref: Path):
    """Their ``models`` and ``main`` modules, with empty stand-ins for the training-only imports."""
    for name in ("wandb", "gym", "safety_gym"):
        sys.modules.setdefault(name, types.ModuleType(name))
    sys.path.insert(0, str(ref))
    import main
    import models
    return main, models


def make_rollout(rng: np.random.Generator) -> tuple[dict, dict]:
    """(the project's inputs, [C]'s rollout dict). Float32 values, as their DataGenerator stores;
    rewards on a 1/64 grid so that [C]'s stored 10·r is exact in float32; some rows terminated
    and some truncated (gym 0.21's ``done`` is either)."""
    f32 = lambda x: np.asarray(x, np.float32)  # noqa: E731
    obs = f32(np.clip(rng.normal(size=(ROWS, OBS)), -5, 5))
    next_obs = f32(np.clip(obs + 0.3 * rng.normal(size=(ROWS, OBS)), -5, 5))
    act = f32(rng.uniform(-1, 1, size=(ROWS, ACT)))
    reward = f32(np.round(rng.normal(size=ROWS) * 64) / 64)
    cost = f32(rng.random(ROWS) < 0.3)
    terminated, truncated = np.zeros(ROWS, bool), np.zeros(ROWS, bool)
    terminated[[3, 40]], truncated[[10, 50]] = True, True
    inputs = {"obs": obs, "next_obs": next_obs, "act": act, "reward": reward, "cost": cost,
              "terminated": terminated, "truncated": truncated}
    rollout = {"states": obs, "actions": act, "next_states": next_obs,
               "reward": f32(reward * C["reward_scaling"])[:, None], "cost": cost[:, None],
               "terminals": (terminated | truncated)[:, None], "buffer_len": ROWS, "avg_cost": EP_COST}
    return inputs, rollout


class Tap:
    """Feeds the recorded noise to ``torch.normal`` and records what the update computes, by
    wrapping the functions it calls (each returns what the wrapped one returns)."""

    def __init__(self, main, models, agent, noise: np.ndarray):
        self.noise = [torch.as_tensor(n) for n in noise.reshape(-1, MB, ACT)]  # per minibatch: z0, z1..zT
        self.used, self.targets, self.chain, self.logp, self.grads, self.clip_norms = 0, [], [], [], [], []
        self.patches = [(torch, "normal", self.normal), (main.F, "mse_loss", self.mse_loss),
                        (torch.nn.utils, "clip_grad_norm_", self.clip),
                        (torch.utils.data, "DataLoader", self.loader)]
        self.orig = {name: getattr(mod, name) for mod, name, _ in self.patches}
        policy_forward, logprob = agent.policy.forward, agent.actor.logprob
        agent.policy.forward = lambda *a, **k: self._keep(self.chain, policy_forward(*a, **k))
        agent.actor.logprob = lambda *a, **k: self._keep(self.logp, logprob(*a, **k))
        names = {}
        for net in ("actor", "reward_critic", "cost_critic"):
            names.update({id(p): f"{net}.{n}" for n, p in getattr(agent, net).named_parameters()})
        for optim in (agent.actor_optimizer, agent.reward_critic_optimizer, agent.cost_critic_optimizer):
            step = optim.step

            def recording_step(*a, _step=step, _optim=optim, **k):
                self.grads.append({names[id(p)]: p.grad.detach().clone()
                                   for g in _optim.param_groups for p in g["params"]})
                return _step(*a, **k)
            optim.step = recording_step

    @staticmethod
    def _keep(store: list, value):
        store.append(value[0].detach().clone() if isinstance(value, tuple) else value.detach().clone())
        return value

    def normal(self, *args, **kwargs):
        at_start = self.used % (C["langevin_steps"] + 1) == 0
        z = self.noise[self.used]
        self.used += 1
        if len(args) == 2 and torch.is_tensor(args[0]):  # GaussianPolicy.get_act: N(mean, std)
            assert at_start, "the chain's start drew noise out of turn"
            return args[0] + args[1] * z
        assert not at_start and args == (0, 1) and tuple(kwargs["size"]) == z.shape, (args, kwargs)
        return z.clone()

    def mse_loss(self, pred, target, *args, **kwargs):
        loss = self.orig["mse_loss"](pred, target, *args, **kwargs)
        self.targets.append((target.detach().clone(), loss.detach().clone()))
        return loss

    def clip(self, params, max_norm, *args, **kwargs):
        norm = self.orig["clip_grad_norm_"](params, max_norm, *args, **kwargs)
        self.clip_norms.append((float(max_norm), float(norm)))
        return norm

    def loader(self, *args, **kwargs):
        return self.orig["DataLoader"](*args, **{**kwargs, "shuffle": False})

    def __enter__(self):
        for mod, name, fn in self.patches:
            setattr(mod, name, fn)
        return self

    def __exit__(self, *exc):
        for mod, name, _ in self.patches:
            setattr(mod, name, self.orig[name])


def build(main, models):
    """Their networks in float64 from seed 0 (the critics' heads ×CRITIC_SLOPE), targets moved off the
    online nets by N(0, 0.05²) (as training leaves them apart; the KL term and the target critics
    then matter), the online log σ moved by N(0, 0.1²); their optimizers; their agent with ν₀ and
    the bound of the past iteration."""
    dtype, device = torch.float64, torch.device("cpu")
    torch.manual_seed(SEED)
    policy = models.LangevinPolicy(OBS, ACT, 1.0, C["eta"], lam=C["lam"], langevin_steps=C["langevin_steps"],
                                   langevin_stepsize=C["langevin_stepsize"], act_grad_norm=C["act_grad_norm"],
                                   dtype=dtype, device=device, wandb=False)
    actor = models.GaussianPolicy(OBS, ACT, (HIDDEN, HIDDEN), "tanh", C["logstd"])
    critic, critic_cost = models.Critic(OBS, ACT, HIDDEN), models.Critic(OBS, ACT, HIDDEN)
    with torch.no_grad():
        for net in (critic, critic_cost):
            for head in (net.q1_model[-1], net.q2_model[-1]):
                head.weight.mul_(CRITIC_SLOPE)
    targets = [copy.deepcopy(net) for net in (actor, critic, critic_cost)]
    with torch.no_grad():
        for net in targets:
            for p in net.parameters():
                p.add_(0.05 * torch.randn_like(p))
        actor.logstd_layer.add_(0.1 * torch.randn_like(actor.logstd_layer))
    optims = [torch.optim.Adam(net.parameters(), lr=LR) for net in (actor, critic, critic_cost)]
    logger = types.SimpleNamespace(update=lambda *a: None, save_model=lambda *a: None)
    agent = main.LAC(None, policy, actor, optims[0], targets[0], critic, critic_cost, targets[1], targets[2],
                     optims[1], optims[2], C["reward_grad_norm"], C["cost_grad_norm"], C["actor_grad_norm"],
                     C["num_epochs"], MB, C["policy_freq"], C["gamma"], C["c_gamma"], C["tau"], C["lam"],
                     NU0, C["nu_lr"], NU_MAX0, C["nu_max_factor"], C["cost_lim"], C["l2_reg"],
                     [0.0], [0.0], logger, False)
    return agent


NETS = ("actor", "actor_target", "reward_critic", "cost_critic", "reward_critic_target", "cost_critic_target")


def weights(agent) -> dict:
    return {f"{net}.{k}": v.detach().clone() for net in NETS for k, v in getattr(agent, net).state_dict().items()}


#: The recorded updates: output prefix → the rows [C]'s ``terminals`` marks (module docstring).
SCENARIOS = {"": ("terminated", "truncated"), "bootstrap/": ("terminated",)}


def update(main, models, rollout: dict, noise: np.ndarray) -> tuple[dict, dict, "Tap"]:
    """[C]'s update from the seeded weights: (the weights before, what it computed, the tap)."""
    agent = build(main, models)
    before = weights(agent)
    with Tap(main, models, agent, noise) as tap:
        agent.update_params(ITERATION, rollout, torch.float64, torch.device("cpu"))
    assert tap.used == noise.shape[0] * noise.shape[1], "not all the recorded noise was drawn"
    out = {"nu": agent.nu, "nu_max": agent.nu_max}
    for k in range(ROWS // MB):
        # F.mse_loss calls: reward Q1, Q2, then cost Q1, Q2 (the same target twice each).
        (y_r, l_r1), (_, l_r2), (y_c, l_c1), (_, l_c2) = tap.targets[4 * k: 4 * k + 4]
        grads = tap.grads[3 * k: 3 * k + 3]  # reward critic, cost critic, actor
        out.update({f"mb{k}/chain": tap.chain[k], f"mb{k}/y_reward": y_r[:, 0], f"mb{k}/y_cost": y_c[:, 0],
                    f"mb{k}/loss_reward_critic": l_r1 + l_r2, f"mb{k}/loss_cost_critic": l_c1 + l_c2,
                    f"mb{k}/loss_actor": -tap.logp[k].mean()})
        for g in grads:
            out.update({f"mb{k}/grad/{n}": v for n, v in g.items()})
    out.update({f"after/{k}": v for k, v in weights(agent).items()})
    return before, out, tap


def record(ref: Path, out_dir: Path) -> Path:
    torch.set_default_dtype(torch.float64)
    main, models = import_reference(ref)
    rng = np.random.default_rng(SEED)
    inputs, rollout = make_rollout(rng)
    noise = rng.normal(size=(ROWS // MB, C["langevin_steps"] + 1, MB, ACT))
    out, taps, before = {}, {}, None
    for prefix, done in SCENARIOS.items():
        terminals = np.logical_or.reduce([inputs[d] for d in done])
        fresh = {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in rollout.items()}
        before_k, out_k, taps[prefix] = update(main, models, {**fresh, "terminals": terminals[:, None]}, noise)
        assert before is None or all(torch.equal(before[k], before_k[k]) for k in before)
        before = before_k
        out.update({f"{prefix}{k}": v for k, v in out_k.items()})
    tap = taps[""]
    commit = subprocess.run(["git", "-C", str(ref), "rev-parse", "HEAD"], capture_output=True, text=True,
                            check=True).stdout.strip()
    chain_norms = [n for bound, n in tap.clip_norms if bound == C["act_grad_norm"]]
    actor_norms = [n for bound, n in tap.clip_norms if bound == C["actor_grad_norm"]]
    meta = {"reference": "Lfh404/LAC (the authors' code)", "reference_version": commit,
            "reference_source": "github.com/Lfh404/LAC main.py LAC.update_params, models.py "
                                "LangevinPolicy/GaussianPolicy/Critic",
            "algorithm": "lac", "command": "REF_PY benchmarks/golden/lac_authors.py --ref ~/ref/LAC",
            "torch": torch.__version__, "obs_dim": OBS, "act_dim": ACT, "rows": ROWS, "minibatch": MB,
            "actor_hidden": [HIDDEN, HIDDEN], "critic_hidden": [HIDDEN] * 3, "iteration": ITERATION,
            "env_steps_lifetime_before": ITERATION * BATCH_STEPS, "lr": LR, "reference_args": C,
            "nu_before": NU0, "nu_max_before": NU_MAX0, "action_bound": 1.0,
            "minibatch_order": "buffer order (their DataLoader's shuffle off)",
            "chain_clip_bound_steps": [int(sum(n > C["act_grad_norm"] for n in norms))  # per minibatch, of T
                                       for norms in np.split(np.array(chain_norms), ROWS // MB)],
            "chain_grad_norm_range": [min(chain_norms), max(chain_norms)],
            "actor_grad_norm_before_clip": actor_norms,
            "scenarios": {prefix.rstrip("/") or "as_trained": {"terminals": list(done)}
                          for prefix, done in SCENARIOS.items()},
            "bootstrap_chain_clip_bound_steps": [
                int(sum(n > C["act_grad_norm"] for n in norms)) for norms in np.split(np.array(
                    [n for bound, n in taps["bootstrap/"].clip_norms if bound == C["act_grad_norm"]]), ROWS // MB)]}
    inputs = {**inputs, "noise": noise, "ep_cost": EP_COST, "nu_before": NU0, "nu_max_before": NU_MAX0}
    return fixture.save(out_dir / "lac-authors.npz", meta, inputs, before, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", type=Path, default=Path.home() / "ref" / "LAC", help="their code's checkout")
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "fixtures" / "golden")
    args = parser.parse_args()
    record(args.ref.expanduser(), args.out)


if __name__ == "__main__":
    main()
