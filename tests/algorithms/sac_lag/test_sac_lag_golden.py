"""SAC-Lag's update is OmniSafe 0.5.0's (tests/fixtures/golden/sac_lag-omnisafe.npz, recorded by
benchmarks/golden/omnisafe_sac_lag.py): two gradient steps from the reference's weights on its two
batches and its recorded noise ε: on the first the reward critics (soft target on the target
critics, α·log π of a' ~ π(·|s')) and the cost critic (target at squash(μ(s'))), each clipped and
Adam-stepped, then λ's Adam step; on the second, a policy-delay step, the same, then the actor on
(α·log π − min Q_R + λ·Q_C)/(1 + λ) at the stepped critics and Polyak of both targets. Every loss,
post-clip gradient, λ and parameter after (targets included) within 1e-5 relative, in float64
(float64 parameters; ``critic_dtype="float32"`` is the critics' plain path, whose arithmetic is the
parameters' dtype); a learner with another Polyak τ, entropy sign, policy delay, cost discount or
λ₀ does not, and the comparison names the output that differs."""

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from lac_rllib.algorithms.sac_lag import learner as L
from lac_rllib.algorithms.sac_lag import module as M
from lac_rllib.algorithms.sac_lag import networks
from lac_rllib.algorithms.sac_lag.config import SACLagConfig
from lac_rllib.constrained.costs import COSTS
from lac_rllib.constrained.metrics import ACTOR_LOSS, CRITIC_LOSS, TS_EPISODE_COSTS
from tests.algorithms.golden import Spaces, assert_matches, load

MID = DEFAULT_MODULE_ID
BATCH = ("obs", "act", "reward", "cost", "done", "next_obs")  # the fixture's batch columns, per step
# OmniSafe's networks -> the module's: the actor's MLP has the same layout; each critic is a member
# of a batched ensemble (weights[k] (E, in, out) = Linear k's weight transposed, biases[k] (E, 1, out)).
ACTOR = "actor.net."
ENSEMBLES = {"reward_critic": "reward_critics", "cost_critic": "cost_critic",
             "target_reward_critic": "target_reward_critics", "target_cost_critic": "target_cost_critic"}


@pytest.fixture(scope="module")
def fx():
    return load("sac_lag-omnisafe")


def omnisafe_named(module, tensors: dict) -> dict:
    """``tensors`` (module parameter name → tensor: parameters or their gradients) under
    OmniSafe's names: ``reward_critic.critic_<j>.0.<2k>.weight`` is member j of ensemble layer k."""
    out = {}
    for name, t in tensors.items():
        t = t.detach()
        if name.startswith(ACTOR):
            out[name] = t.numpy()
            continue
        ours, kind, k = name.rsplit(".", 2)  # e.g. reward_critics.weights.0
        net = {v: n for n, v in ENSEMBLES.items()}[ours]
        for j in range(t.shape[0]):
            key = f"{net}.critic_{j}.0.{2 * int(k)}"
            out[f"{key}.weight" if kind == "weights" else f"{key}.bias"] = (
                t[j].t().numpy() if kind == "weights" else t[j, 0].numpy())
    return out


def load_weights(module, before: dict) -> None:
    """The reference's starting weights into the module, as float64 parameters."""
    params = dict(module.named_parameters())
    for name, p in params.items():
        if name.startswith(ACTOR):
            value = torch.as_tensor(before[name])
        else:
            ours, kind, k = name.rsplit(".", 2)
            net = {v: n for n, v in ENSEMBLES.items()}[ours]
            members = [before[f"{net}.critic_{j}.0.{2 * int(k)}.{'weight' if kind == 'weights' else 'bias'}"]
                       for j in range(p.shape[0])]
            value = torch.stack([torch.as_tensor(m).t() if kind == "weights" else torch.as_tensor(m)[None]
                                 for m in members])
        assert value.shape == p.shape, name
        p.data = value.to(torch.float64).clone()


def build(fx, **fields):
    """The project's learner with the reference's hyperparameters (the fixture's meta): its
    SafetyPointGoal1 preset, the recording's overrides, critics on the plain (parameter-dtype) path."""
    algo, lag = fx.meta["algo_cfgs"], fx.meta["lagrange_cfgs"]
    hidden = tuple(fx.meta["hidden"])
    reference = dict(
        actor_hidden=hidden, critic_hidden=hidden, critic_dtype="float32", obs_normalization=False,
        alpha=fx.meta["alpha_used"], gamma=algo["gamma"], cost_gamma=algo["gamma"],
        actor_lr=fx.meta["lr"], critic_lr=fx.meta["critic_lr"], max_grad_norm=float(algo["max_grad_norm"]),
        polyak_tau=algo["polyak"], policy_delay=algo["policy_delay"],
        nu_init=lag["lagrangian_multiplier_init"], lagrangian_lr=lag["lambda_lr"], lagrangian_rule="adam",
        cost_limit=lag["cost_limit"], warmup_env_steps=0)
    config = SACLagConfig().task(fx.meta["task"]).training(**{**reference, **fields})
    learner = config.build_learner(env=Spaces(fx.inputs["step1/obs"].shape[1], fx.inputs["step1/act"].shape[1]))
    module = learner.module[MID].unwrapped()
    load_weights(module, fx.before)
    eps = [torch.as_tensor(fx.inputs[f"eps/{i}"]) for i in range(sum(k.startswith("eps/") for k in fx.inputs))]

    def recorded_noise(like):
        if not eps:  # more samples than the reference drew: zeros, and the draw counts differ
            return torch.zeros_like(like)
        e = eps.pop(0)
        assert e.shape == like.shape
        return e.to(like.dtype)

    module.standard_normal = recorded_noise  # the reference's ε, in the order it drew them
    return learner, eps


def take_step(learner, batch: dict, ep_cost: float) -> dict:
    """One gradient step through the learner's hooks (``TorchLearner._uncompiled_update``'s order);
    each optimizer's gradients as its ``step`` reads them (after the clip), the critics' two
    losses from the learner's own targets, the actor's as it logged it."""
    module = learner.module[MID].unwrapped()
    names = {id(p): n for n, p in module.named_parameters()}
    grads = {}
    for _, optim in learner.get_optimizers_for_module(MID):
        def recording_step(*a, _step=optim.step, _optim=optim, **kw):
            grads.update({names[id(p)]: p.grad.clone() for g in _optim.param_groups for p in g["params"]
                          if p.grad is not None})
            return _step(*a, **kw)
        optim.step = recording_step
    learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [ep_cost], NUM_ENV_STEPS_SAMPLED_LIFETIME: 1})
    fwd = learner.module.forward_train({MID: batch})
    config = learner.config.get_config_for_module(MID)
    with torch.no_grad():
        y_r, y_c = L.critic_targets(batch, fwd[MID], config)
        q_r, q_c = fwd[MID][M.Q_REWARD], fwd[MID][M.Q_COST]
        out = {"loss_reward_critic": float(((q_r - y_r) ** 2).mean(-1).sum()),
               "loss_cost_critic": float(((q_c - y_c) ** 2).mean()),
               "q_reward_1_mean": float(q_r[0].mean()), "q_cost_mean": float(q_c.mean())}
    losses = learner.compute_losses(fwd_out=fwd, batch={MID: batch})
    actor_step = learner.is_actor_step()
    learner.apply_gradients(learner.postprocess_gradients(learner.compute_gradients(losses)))
    # The learner's own critic loss is the sum of the two recomputed here.
    assert float(learner._last[MID][CRITIC_LOSS]) == pytest.approx(out["loss_reward_critic"] + out["loss_cost_critic"],
                                                                   rel=1e-12)
    if actor_step:
        out["loss_pi"] = float(learner._last[MID][ACTOR_LOSS])
    out["nu"] = float(module.nu)
    out.update({f"grad/{k}": v for k, v in omnisafe_named(module, grads).items()})
    return out


def golden_steps(fx, **fields) -> dict:
    """The fixture's two updates taken by the project's learner; its outputs under the reference's names."""
    learner, eps = build(fx, **fields)
    module = learner.module[MID].unwrapped()
    out = {}
    for k in range(1, fx.meta["updates"] + 1):
        b = {n: torch.as_tensor(fx.inputs[f"step{k}/{n}"]) for n in BATCH}
        batch = {Columns.OBS: b["obs"], Columns.ACTIONS: b["act"], Columns.REWARDS: b["reward"], COSTS: b["cost"],
                 Columns.TERMINATEDS: b["done"].bool(), Columns.NEXT_OBS: b["next_obs"]}
        drawn = len(eps)
        out.update({f"step{k}/{n}": v for n, v in take_step(learner, batch, float(fx.inputs["ep_cost"])).items()})
        out[f"step{k}/noise_draws"] = drawn - len(eps)
    out.update({f"after/{k}": v for k, v in omnisafe_named(module, dict(module.named_parameters())).items()})
    return out


def test_the_learner_takes_omnisafes_two_steps_in_float64(fx):
    got = golden_steps(fx)
    assert_matches(got, fx.outputs)
    assert len(fx.outputs) > 90 and all(k in got for k in fx.outputs)


def test_with_omnisafes_float32_log_2_every_output_agrees_to_float64_rounding(fx, monkeypatch):
    """The 1e-5 above hides nothing: what is left (up to ~4e-6, in the reward critics' gradients)
    is OmniSafe's log 2, a float32 buffer of its actor that ``.double()`` widens 1.9e-9 off; with
    that value, every output agrees to 1e-11."""
    monkeypatch.setattr(networks, "LOG_2", float(torch.log(torch.tensor(2.0, dtype=torch.float32))))
    assert_matches(golden_steps(fx), fx.outputs, rtol=1e-11, atol=1e-14)


@pytest.mark.parametrize("fields, differs", [
    ({"polyak_tau": 0.01}, "after/target_reward_critic"),  # Polyak τ
    ({"policy_delay": 1}, "step1/noise_draws"),  # the actor steps on every update
    ({"cost_gamma": 0.9}, "step1/loss_cost_critic"),  # the cost target's discount
    ({"nu_init": 0.4}, "step1/nu"),  # λ₀
])
def test_a_perturbed_learner_fails_naming_the_output(fx, fields, differs):
    with pytest.raises(AssertionError, match=differs):
        assert_matches(golden_steps(fx, **fields), fx.outputs)


def test_the_entropy_term_with_its_sign_flipped_fails(fx, monkeypatch):
    real = L.critic_targets

    def flipped(batch, fwd_out, config):  # y_R with +α·log π(a'|s'): a sign error in the soft target
        return real(batch, {**fwd_out, M.LOGP_NEXT: -fwd_out[M.LOGP_NEXT]}, config)

    monkeypatch.setattr(L, "critic_targets", flipped)
    with pytest.raises(AssertionError, match="step1/loss_reward_critic"):
        assert_matches(golden_steps(fx), fx.outputs)
