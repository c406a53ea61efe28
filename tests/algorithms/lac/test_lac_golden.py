"""LAC's golden step: the project's learner reproduces one update of the authors' code
(github.com/Lfh404/LAC, tests/fixtures/golden/lac-authors.npz, recorded by
benchmarks/golden/lac_authors.py) to 1e-5 relative, fed the same batch, weights, noise and
hyperparameters; and at β > 0, which their code lacks, the actor's loss and gradient against eq. (16)
written out here.

The update is [C]'s ``LAC.update_params`` at iteration 1 (main.py:101-244): ν's projected step, then
two minibatches of 32, each with the chain at s' (T = 30, η = 1e-4, λ = 1e-4; the batch clip 1000
binds at none of the first minibatch's steps and at every one of the second's), the twin critics'
step, the actor's maximum-likelihood step and Polyak of every target; then the next bound ν_max.
The learner takes it through its own hooks in RLlib's order (``before_gradient_based_update``, per
minibatch forward_train / compute_losses / compute_gradients / postprocess_gradients /
apply_gradients, ``after_gradient_based_update``), with the chain's noise given through
``LACTorchRLModule.langevin(noise=...)``.

The project's default path is checked too: the fused chain (``langevin_fused=True``, compiled by
torch.compile) and targets that bootstrap past a time-limit truncation (``bootstrap_on_truncation``)
against the fixture's ``bootstrap/`` update, [C]'s own update on the same buffer with only the
terminated rows in its ``terminals`` (its code has no fused chain; β > 0, which it also lacks, is
eq. (16) below). The fused chain multiplies in float32 by construction (energy.make_grad_fn's
matmul dtype, energy._mm's cast of each product); :func:`fused_in_float64` lifts those two and
nothing else, and at the recorded inputs that chain equals the eager one to 1e-12: end points,
energies (where 1/λ and ν/λ enter), gradient norms, clip fractions."""

from __future__ import annotations

import contextlib
import math
from unittest import mock

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.algorithms.lac import energy
from lac_rllib.algorithms.lac import module as M
from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.algorithms.lac.learner import critic_targets
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import ACTOR_KL, ACTOR_LOSS, CRITIC_LOSS, TS_ITERATION, TS_MEAN_EPISODE_COST
from tests.algorithms.golden import Spaces, assert_matches, load

FX = load("lac-authors")
MID = DEFAULT_MODULE_ID
#: Where the project's defaults differ from [C]'s (docs/spec.md; [C]'s argparse, main.py:397-469).
AUTHORS_FIELDS = dict(
    temperature=1e-4,  # λ: [C]'s default (its README command passes no --lam); ours is Table 4-5's 1e-3
    bootstrap_on_truncation=False,  # [C] stores gym 0.21's done: a time-limit truncation is terminal
    lr_decay_horizon=2_500_000,  # [C]: lr × (1 − 0.5·it/125) over 125 iterations of 20k env steps
    cost_limit=25.0,  # [C]'s --limits default (ours: the task's)
)
#: The fixture's shapes, and what the step needs here: no observation filter (the batch is
#: already normalised, as [C]'s buffer is) and the eager chain (the fused one runs in float32).
SHAPE = dict(actor_hidden=tuple(FX.meta["actor_hidden"]), critic_hidden=tuple(FX.meta["critic_hidden"]),
             obs_normalization=False, langevin_fused=False)
#: The project's defaults where [C]'s update can take them: the fused chain, targets that bootstrap
#: past a truncation (the fixture's ``bootstrap/`` update); the other fields as AUTHORS_FIELDS.
DEFAULT_PATH = dict(langevin_fused=True, bootstrap_on_truncation=True)
#: What the chain returns besides its end points, compared between the fused and eager chains.
CHAIN_DIAGNOSTICS = ("energy_start", "energy_end", "grad_norm", "clip_fraction", "at_bound")
# [C]'s layers → ours: GaussianPolicy (mlp_net, mean_layer, logstd_layer) → GaussianActor.mean_net,
# log_std; the twin Critics (q1_model, q2_model: Linear at 0, 2, 4, 6) → the ensemble's members
# [Q_R1, Q_R2, Q_C1, Q_C2], layer k's weight transposed (E, in, out), bias (E, 1, out).
ACTOR_LAYERS = {"mlp_net.0": "mean_net.0", "mlp_net.2": "mean_net.2", "mean_layer": "mean_net.4"}
ACTORS = {"actor": "actor", "actor_target": "target_actor"}
CRITICS = {"critics": ("reward_critic", "cost_critic"),
           "target_critics": ("reward_critic_target", "cost_critic_target")}
MEMBERS = ("q1_model", "q2_model")


def to_project(named: dict, prefix: str = "") -> dict:
    """[C]'s tensors (``<prefix><net>.<param>``) under the module's parameter names."""
    out = {}
    for theirs, ours in ACTORS.items():
        for layer, mine in ACTOR_LAYERS.items():
            for kind in ("weight", "bias"):
                key = f"{prefix}{theirs}.{layer}.{kind}"
                if key in named:
                    out[f"{ours}.{mine}.{kind}"] = torch.as_tensor(named[key])
        if f"{prefix}{theirs}.logstd_layer" in named:
            out[f"{ours}.log_std"] = torch.as_tensor(named[f"{prefix}{theirs}.logstd_layer"]).reshape(-1)
    for ours, nets in CRITICS.items():
        for k in range(4):
            keys = [f"{prefix}{net}.{m}.{2 * k}" for net in nets for m in MEMBERS]
            if f"{keys[0]}.weight" in named:
                out[f"{ours}.weights.{k}"] = torch.stack([torch.as_tensor(named[f"{key}.weight"]).T for key in keys])
                out[f"{ours}.biases.{k}"] = torch.stack([torch.as_tensor(named[f"{key}.bias"])[None] for key in keys])
    return out


def to_authors(named: dict, prefix: str) -> dict:
    """The module's tensors under [C]'s names (the inverse of :func:`to_project`)."""
    out = {}
    for theirs, ours in ACTORS.items():
        for layer, mine in ACTOR_LAYERS.items():
            for kind in ("weight", "bias"):
                if f"{ours}.{mine}.{kind}" in named:
                    out[f"{prefix}{theirs}.{layer}.{kind}"] = named[f"{ours}.{mine}.{kind}"]
        if f"{ours}.log_std" in named:
            out[f"{prefix}{theirs}.logstd_layer"] = named[f"{ours}.log_std"].reshape(1, -1)
    for ours, nets in CRITICS.items():
        for k in range(4):
            if f"{ours}.weights.{k}" in named:
                keys = [f"{prefix}{net}.{m}.{2 * k}" for net in nets for m in MEMBERS]
                for e, key in enumerate(keys):
                    out[f"{key}.weight"] = named[f"{ours}.weights.{k}"][e].T
                    out[f"{key}.bias"] = named[f"{ours}.biases.{k}"][e, 0]
    return {k: v.detach().numpy() for k, v in out.items()}


def build(**fields):
    """The project's learner on the fixture's spaces, [C]'s fields, float64 weights from the fixture,
    ν and its bound as [C]'s update found them, and the learning rate of iteration 1."""
    config = LACConfig().training(**{**SHAPE, **AUTHORS_FIELDS, **fields})
    learner = config.build_learner(env=Spaces(FX.meta["obs_dim"], FX.meta["act_dim"]))
    module = learner.module[MID].unwrapped()
    params = dict(module.named_parameters())
    for name, value in to_project(FX.before).items():
        params[name].data = value.to(torch.float64).reshape(params[name].shape).clone()
    assert len(to_project(FX.before)) == len(params)
    module.nu.fill_(float(FX.inputs["nu_before"]))
    learner.multipliers[MID].bound.value = float(FX.inputs["nu_max_before"])
    # The end of iteration 0, as the run's loop calls it: the lr schedules step to its env steps.
    steps = FX.meta["env_steps_lifetime_before"]
    learner.after_gradient_based_update(timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: steps})
    return learner


def peek(learner, key: str) -> float:
    """The learner's last logged ``key`` (the losses are logged with their graph: detached here)."""
    return float(torch.as_tensor(learner.metrics.peek((MID, key))).detach())


def minibatch(k: int) -> dict:
    mb = FX.meta["minibatch"]
    i = {name: torch.as_tensor(v[k * mb:(k + 1) * mb]) for name, v in FX.inputs.items()
         if np.ndim(v) and name != "noise"}
    return {Columns.OBS: i["obs"].double(), Columns.NEXT_OBS: i["next_obs"].double(),
            Columns.ACTIONS: i["act"].double(), Columns.REWARDS: i["reward"].double(), COSTS: i["cost"].double(),
            Columns.TERMINATEDS: i["terminated"], Columns.TRUNCATEDS: i["truncated"]}


def forward(learner, k: int):
    """forward_train of minibatch k with the recorded chain noise; (batch, fwd_out, the chain's result)."""
    module = learner.module[MID].unwrapped()
    noise = torch.as_tensor(FX.inputs["noise"][k])
    chains = []

    def langevin(*args, **kwargs):
        chains.append(M.LACTorchRLModule.langevin(module, *args, noise=noise, **kwargs))
        return chains[-1]

    module.langevin = langevin
    try:
        batch = minibatch(k)
        fwd = learner.module.forward_train({MID: batch})
    finally:
        del module.langevin
    assert len(chains) == 1, "one chain per minibatch (actor_chain_at='next', as [C])"
    return batch, fwd, chains[0]


def update(**fields) -> dict:
    """[C]'s update taken by the project's learner; its outputs under [C]'s names."""
    learner = build(**fields)
    module, config = learner.module[MID].unwrapped(), learner.config.get_config_for_module(MID)
    learner.before_gradient_based_update(timesteps={TS_ITERATION: FX.meta["iteration"],
                                                    TS_MEAN_EPISODE_COST: float(FX.inputs["ep_cost"])})
    out = {"nu": float(module.nu)}
    names = {id(p): n for n, p in module.named_parameters()}
    for k in range(len(FX.inputs["noise"])):
        batch, fwd, result = forward(learner, k)
        chain = result.action
        out.update({f"mb{k}/chain_{name}": getattr(result, name).numpy() for name in CHAIN_DIAGNOSTICS})
        losses = learner.compute_losses(fwd_out=fwd, batch={MID: batch})
        grads = learner.postprocess_gradients(learner.compute_gradients(losses))
        stepped = {names[id(p)]: g.detach().clone() for p, g in grads.items() if g is not None}
        learner.apply_gradients(grads)
        q = fwd[MID][M.Q_PRED].detach()
        y_r, y_c = critic_targets(batch, fwd[MID][M.Q_TARGET_NEXT], module.critics.n_reward, config)
        out.update({f"mb{k}/chain": chain.numpy(), f"mb{k}/y_reward": y_r.numpy(), f"mb{k}/y_cost": y_c.numpy(),
                    f"mb{k}/loss_reward_critic": float(((q[:2] - y_r) ** 2).mean(-1).sum()),
                    f"mb{k}/loss_cost_critic": float(((q[2:] - y_c) ** 2).mean(-1).sum()),
                    f"mb{k}/loss_critic": peek(learner, CRITIC_LOSS), f"mb{k}/loss_actor": peek(learner, ACTOR_LOSS)})
        out.update(to_authors(stepped, f"mb{k}/grad/"))
    # The iteration's end sets the next bound (the lr it steps to is not compared).
    steps = FX.meta["env_steps_lifetime_before"]
    learner.after_gradient_based_update(timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: steps})
    out["nu_max"] = learner.multipliers[MID].bound.value
    out.update(to_authors(dict(module.named_parameters()), "after/"))
    return out


def expected(scenario: str = "") -> dict:
    """The outputs of the fixture's update ``scenario`` ("" as [C] trains, "bootstrap/"), plus the
    critics' summed loss (ours logs one critic loss)."""
    n = len(FX.inputs["noise"])
    outputs = {k[len(scenario):]: v for k, v in FX.outputs.items()
               if k.startswith(scenario) and (scenario or not k.startswith("bootstrap/"))}
    return {**outputs, **{f"mb{k}/loss_critic": outputs[f"mb{k}/loss_reward_critic"]
                          + outputs[f"mb{k}/loss_cost_critic"] for k in range(n)}}


@contextlib.contextmanager
def fused_in_float64():
    """The fused chain with its two float32 steps lifted, the matmuls' input dtype ("float32", the
    default of ``langevin_dtype``, taken as the weights' float64) and ``_mm``'s cast of each product
    to float32; everything else is the fused path's own code as the default runs it (torch.compile
    of energy.energy_and_grad: the selection, the energy with its 1/λ and ν/λ, the backward
    written out, the Gaussian term)."""
    with (mock.patch.object(energy, "TORCH_DTYPES", {**energy.TORCH_DTYPES, "float32": torch.float64}),
          mock.patch.object(energy, "_mm", lambda x, w: torch.bmm(x.to(w.dtype), w))):
        yield


@pytest.fixture(scope="module")
def ours():
    return update()


@pytest.fixture(scope="module")
def default_path():
    """The update on the default path (DEFAULT_PATH, the fused chain compiled in float64), and the
    same update with the eager chain."""
    with fused_in_float64():
        fused = update(**DEFAULT_PATH)
    assert not energy._compile_failed, "torch.compile fell back to eager: the fused chain was not compiled"
    return fused, update(**{**DEFAULT_PATH, "langevin_fused": False})


def test_fixture_names_the_authors_commit():
    assert FX.meta["reference_version"] == "45f146ba76986cf4c9867f7022ecbfade5b55189"
    assert FX.meta["reference_args"]["lam"] == AUTHORS_FIELDS["temperature"]


def test_reproduces_the_authors_update(ours):
    """Every recorded output (ν, ν_max, each minibatch's chain end points, targets, losses and the
    gradients each optimizer stepped on, every parameter and target after) to 1e-5 relative."""
    assert_matches(ours, expected())


def test_the_default_path_reproduces_the_authors_bootstrapped_update(default_path):
    """The fused chain and bootstrap on truncation against [C]'s update with only the terminated
    rows terminal: every output to 1e-5 relative. The bootstrap changes mb0's targets on its
    truncated row (10) only, and everything from mb1 on (its critics stepped on them)."""
    fused, _ = default_path
    assert FX.meta["scenarios"]["bootstrap"] == {"terminals": ["terminated"]}
    assert_matches(fused, expected("bootstrap/"))
    changed = ~np.isclose(FX.outputs["mb0/y_reward"], FX.outputs["bootstrap/mb0/y_reward"], rtol=1e-9, atol=0)
    assert list(np.flatnonzero(changed)) == list(np.flatnonzero(FX.inputs["truncated"][:FX.meta["minibatch"]]))
    with pytest.raises(AssertionError, match="mb0/y_reward"):  # the authors' training semantics differ
        assert_matches(fused, expected())


def test_the_fused_chain_is_the_eager_chain_at_the_recorded_inputs(default_path):
    """The chains of both minibatches (mb0's at the recorded weights, states, noise and ν; mb1's
    after the same first step), the fused one compiled: end points, the energy at the start and the
    end (E = (ν·max Q_C − min Q_R)/λ − log π: the temperature and ν enter here), the gradient's
    mean norm, the fraction of steps clipped (none in mb0, all in mb1) and at the bounds, to 1e-12
    relative; the rest of the update to 1e-10."""
    fused, eager = default_path
    assert [float(eager[f"mb{k}/chain_clip_fraction"]) for k in (0, 1)] == [0.0, 1.0]
    assert_matches(fused, eager, rtol=1e-12, atol=1e-14, only=("mb0/chain", "mb1/chain"))
    assert_matches(fused, eager, rtol=1e-10, atol=1e-14)


def test_fixture_exercises_the_chain_clip_and_bounds():
    """The chain's batch clip bound at some steps and not at others (meta: per minibatch), and some
    end points sit on the action bound: both branches of each are in the comparison."""
    bound, steps = sum(FX.meta["chain_clip_bound_steps"]), FX.meta["reference_args"]["langevin_steps"]
    assert 0 < bound < steps * len(FX.inputs["noise"])
    chain = np.concatenate([FX.outputs[f"mb{k}/chain"] for k in range(len(FX.inputs["noise"]))])
    assert 0 < np.mean(np.abs(chain) == 1.0) < 0.5


@pytest.mark.parametrize("field, value, differs", [
    ("beta", 1.0, "mb0/loss_actor"),
    ("langevin_step_size", 2e-4, "mb0/chain"),
])
def test_a_perturbed_learner_fails_naming_the_output(field, value, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(update(**{field: value}), expected())


# ----- β > 0: eq. (16) by hand -----
def _mean(weights: list, s: torch.Tensor) -> torch.Tensor:
    """μ_φ(s) of the (16, 16) tanh actor, written out."""
    (w1, b1), (w2, b2), (w3, b3) = weights
    return torch.tanh(torch.tanh(s @ w1.T + b1) @ w2.T + b2) @ w3.T + b3


def hand_actor_loss(beta: float, a: torch.Tensor, s: torch.Tensor):
    """Eq. (16) at s* = s', ã = the chain's end points, from the fixture's starting weights:

        L = mean_b Σ_i [ (ã_i − μ_i)²/(2σ_i²) + log σ_i + ½ log 2π ]
            + β · mean_b Σ_i [ log σ'_i − log σ_i + (σ_i² + (μ_i − μ'_i)²)/(2σ'_i²) − ½ ]

    (μ, σ) the actor's, (μ', σ') the target actor's; returns (L, KL, dL/dθ by [C]'s names)."""
    p = lambda name: torch.tensor(FX.before[name], dtype=torch.float64)  # noqa: E731
    layers = [(p(f"actor.{n}.weight").requires_grad_(), p(f"actor.{n}.bias").requires_grad_()) for n in ACTOR_LAYERS]
    log_std = p("actor.logstd_layer").reshape(-1).requires_grad_()
    mu_t = _mean([(p(f"actor_target.{n}.weight"), p(f"actor_target.{n}.bias")) for n in ACTOR_LAYERS], s)
    log_std_t = p("actor_target.logstd_layer").reshape(-1)
    mu = _mean(layers, s)
    nll = ((a - mu) ** 2 / (2 * torch.exp(2 * log_std)) + log_std + 0.5 * math.log(2 * math.pi)).sum(-1).mean()
    kl = (log_std_t - log_std + (torch.exp(2 * log_std) + (mu - mu_t) ** 2) / (2 * torch.exp(2 * log_std_t))
          - 0.5).sum(-1).mean()
    loss = nll + beta * kl
    flat = [t for layer in layers for t in layer] + [log_std]
    grads = torch.autograd.grad(loss, flat)
    names = [f"actor.{n}.{kind}" for n in ACTOR_LAYERS for kind in ("weight", "bias")] + ["actor.logstd_layer"]
    grads = {n: g.reshape(FX.before[n].shape).numpy() for n, g in zip(names, grads)}
    return float(loss.detach()), float(kl.detach()), grads


def test_actor_loss_and_gradient_with_kl_match_eq_16():
    """β = 5 (their code has no KL term): the learner's actor loss, its KL and the actor's gradient
    (before the clip) equal eq. (16) computed by hand on the first minibatch to 1e-10 relative;
    the KL is far from 0 (the target actor differs), so the term is exercised."""
    beta = 5.0
    learner = build(beta=beta)
    learner.before_gradient_based_update(timesteps={TS_ITERATION: FX.meta["iteration"],
                                                    TS_MEAN_EPISODE_COST: float(FX.inputs["ep_cost"])})
    batch, fwd, result = forward(learner, 0)
    chain = result.action
    losses = learner.compute_losses(fwd_out=fwd, batch={MID: batch})
    grads = learner.compute_gradients(losses)
    by_id = {id(p): g for p, g in grads.items()}
    actor = learner.module[MID].unwrapped().actor
    got = to_authors({f"actor.{n}": by_id[id(p)] for n, p in actor.named_parameters()}, "")
    loss, kl, want = hand_actor_loss(beta, chain, batch[Columns.NEXT_OBS])
    assert kl > 1e-3
    assert peek(learner, ACTOR_KL) == pytest.approx(kl, rel=1e-10)
    assert peek(learner, ACTOR_LOSS) == pytest.approx(loss, rel=1e-10)
    assert sorted(got) == sorted(want)
    assert_matches(got, want, rtol=1e-10, atol=1e-14)
    # The KL term moves the gradient well beyond the tolerance: a learner dropping it fails above.
    _, _, without_kl = hand_actor_loss(0.0, chain, batch[Columns.NEXT_OBS])
    with pytest.raises(AssertionError, match="actor.logstd_layer"):
        assert_matches(without_kl, want, rtol=1e-10, atol=1e-14)
    # β = 0 gives the recorded golden loss: the KL term is the only difference.
    assert peek(learner, ACTOR_LOSS) - beta * kl == pytest.approx(float(FX.outputs["mb0/loss_actor"]), rel=1e-9)
