"""Golden steps: the fixtures recorded from reference implementations' own code
(benchmarks/golden/, tests/fixtures/golden/README.md) and the harness that feeds the project's
learners the same inputs, weights and hyperparameters.

:func:`load` reads a fixture (refusing one whose meta does not name its reference and version);
:func:`on_policy_step` builds an on-policy learner on the fixture's spaces and networks in float64,
loads the reference's weights, takes the step the reference took (the multiplier's, then one
minibatch through the learner's own hooks, RLlib's order) and returns what the reference recorded
under the reference's names (for a fixture with a rollout, also the advantages and value targets
the learner connector makes of it: :func:`connector_step`); :func:`assert_matches` compares and
names every output that differs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, VF_LOSS_KEY
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.evaluation.postprocessing import Postprocessing

from lac_rllib.constrained.metrics import COST_VF_LOSS, TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES, COST_VALUE_TARGETS

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "golden"
REQUIRED_META = ("reference", "reference_version", "algorithm", "command")  # benchmarks/golden/fixture.py
RTOL = 1e-5
#: The buffer's advantages and targets are float32 on both sides (OmniSafe's buffer, RLlib's
#: ``compute_value_targets``): compared to 1e-5 relative and, for entries near 0, 2e-6 absolute (a
#: few float32 ulps of the targets, which reach 30).
BUFFER_ATOL = 2e-6


class FixtureError(ValueError):
    pass


@dataclasses.dataclass
class Fixture:
    name: str
    meta: dict
    inputs: dict
    before: dict
    outputs: dict


def load(name: str, directory: Path = FIXTURES) -> Fixture:
    """The fixture ``name`` (``<algo>-<reference>``); refused when its meta does not say which
    reference and which version of it produced it (a recording nobody can reproduce)."""
    path = directory / f"{name}.npz"
    if not path.exists():
        raise FixtureError(f"no golden fixture {path.name} in {directory}")
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        missing = [k for k in REQUIRED_META if not meta.get(k)]
        if missing:
            raise FixtureError(f"golden fixture {path.name}: its meta lacks {missing} (which reference, which "
                               "version, which command recorded it); record it again with benchmarks/golden/")
        groups = {"in": {}, "before": {}, "out": {}}
        for key in z.files:
            if key != "meta":
                prefix, rest = key.split("/", 1)
                groups[prefix][rest] = z[key]
    return Fixture(name, meta, groups["in"], groups["before"], groups["out"])


def assert_matches(got: dict, expected: dict, *, rtol: float = RTOL, atol: float = 1e-10, only=None) -> None:
    """Every expected output (or those whose name starts with one of ``only``) equal to ``got``'s
    within ``rtol`` relative (``atol`` for values at 0); the message lists each output that differs
    with its largest relative error, or that is missing."""
    keys = [k for k in expected if only is None or k.startswith(tuple(only))]
    bad = []
    for key in keys:
        if key not in got:
            bad.append(f"{key}: not computed")
            continue
        want, have = np.asarray(expected[key], np.float64), np.asarray(got[key], np.float64)
        if want.shape != have.shape:
            bad.append(f"{key}: shape {have.shape}, the reference's {want.shape}")
            continue
        err = np.abs(have - want)
        if not np.all(err <= atol + rtol * np.abs(want)):
            rel = float(np.max(err / np.maximum(np.abs(want), atol)))
            bad.append(f"{key}: max relative error {rel:.3g}")
    assert keys, "no outputs compared"
    assert not bad, "differs from the reference's step:\n  " + "\n  ".join(bad)


class Spaces(gym.Env):
    """An env that is only its spaces: what a learner is built from."""

    def __init__(self, obs_dim: int, act_dim: int):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (act_dim,), np.float32)


# OmniSafe's on-policy actor-critic parameter names -> the project's RLModule's (ppo_lag/module.py).
OMNISAFE_ON_POLICY = {
    "actor.log_std": "pi.log_std",
    "actor.mean.0": "encoder.actor_encoder.net.mlp.0", "actor.mean.2": "encoder.actor_encoder.net.mlp.2",
    "actor.mean.4": "pi.net.mlp.0",
    "reward_critic.critic_0.0": "encoder.critic_encoder.net.mlp.0",
    "reward_critic.critic_0.2": "encoder.critic_encoder.net.mlp.2", "reward_critic.critic_0.4": "vf.net.mlp.0",
    "cost_critic.critic_0.0": "cost_vf.encoder.net.mlp.0", "cost_critic.critic_0.2": "cost_vf.encoder.net.mlp.2",
    "cost_critic.critic_0.4": "cost_vf.head.net.mlp.0",
}


def ours(name: str, mapping: dict) -> str:
    for prefix in sorted(mapping, key=len, reverse=True):
        if name == prefix or name.startswith(prefix + "."):
            return mapping[prefix] + name[len(prefix):]
    raise KeyError(name)


def build_on_policy(config_cls, fx: Fixture, preset=None, **fields):
    """The project's learner for ``fx``: its task's preset (OmniSafe's defaults on Safety-Gymnasium)
    or ``preset``, the fixture's network
    widths, float64 parameters holding the reference's starting weights (ν stays a float32 buffer,
    as OmniSafe's λ is a float32 parameter)."""
    obs_dim, act_dim = fx.inputs["obs"].shape[1], fx.inputs["act"].shape[1]
    config = (config_cls().task(fx.meta["task"], **({"preset": preset} if preset else {}))
              .training(hidden=tuple(fx.meta["hidden"]), obs_normalization=False, **fields))
    learner = config.build_learner(env=Spaces(obs_dim, act_dim))
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    params = dict(module.named_parameters())
    for name, value in fx.before.items():
        p = params[ours(name, OMNISAFE_ON_POLICY)]
        p.data = torch.as_tensor(value, dtype=torch.float64).reshape(p.shape).clone()
    learner.reports_minibatch = True
    return learner


def on_policy_batch(fx: Fixture) -> dict:
    i = {k: torch.as_tensor(v) for k, v in fx.inputs.items() if np.ndim(v)}
    return {Columns.OBS: i["obs"], Columns.ACTIONS: i["act"], Columns.ACTION_LOGP: i["logp"],
            Columns.LOSS_MASK: torch.ones(len(i["obs"]), dtype=torch.bool),
            Postprocessing.ADVANTAGES: i["adv_r"], Postprocessing.VALUE_TARGETS: i["target_value_r"],
            COST_ADVANTAGES: i["adv_c"], COST_VALUE_TARGETS: i["target_value_c"],
            Columns.ACTION_DIST_INPUTS: torch.cat([i["old_mean"], i["old_log_std"]], dim=-1)}


def minibatch_step(learner, batch: dict) -> dict:
    """One minibatch through the learner's hooks as ``TorchLearner._uncompiled_update`` calls them;
    the gradients each optimizer stepped on, by the module's parameter names."""
    mid = DEFAULT_MODULE_ID
    fwd = learner.module.forward_train({mid: batch})
    losses = learner.compute_losses(fwd_out=fwd, batch={mid: batch})
    grads = learner.postprocess_gradients(learner.compute_gradients(losses))
    names = {id(p): n for n, p in learner.module[mid].unwrapped().named_parameters()}
    stepped = {names[id(ref)]: g.detach().clone() for ref, g in grads.items() if g is not None}
    learner.apply_gradients(grads)
    return stepped


def multiplier_step(learner, fx: Fixture) -> float:
    """The multiplier's step on the recorded episode cost; returns ν after it. Both sides keep ν in
    float32 (OmniSafe's λ is a float32 parameter stepped by torch's Adam, the project's a float32
    buffer stepped in double precision), so the two can differ in the last float32 bit (1e-7
    relative): ν is compared as it came out, then the gradient steps start from the reference's ν,
    so that float32 rounding does not leak into the float64 comparisons downstream."""
    learner.before_gradient_based_update(timesteps={TS_EPISODE_COSTS: [float(fx.inputs["ep_cost"])]})
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    nu = float(module.nu)
    if "nu" in fx.outputs:
        module.nu.fill_(float(fx.outputs["nu"]))
    return nu


def rollout_episodes(fx: Fixture) -> list:
    """The fixture's rollout (``in/rollout/*``, ``meta["rollout_chunks"]``) as the episode chunks an
    env runner hands the learner: the batch's rows in order, split into chunks, each with the
    observation after its last row, the step costs in ``info["cost"]`` and the behaviour policy's
    outputs; a chunk ends terminated, truncated (a time limit) or neither (cut at the batch's end)."""
    i = fx.inputs
    spaces = Spaces(i["obs"].shape[1], i["act"].shape[1])
    dist_inputs = np.concatenate([i["old_mean"], i["old_log_std"]], axis=-1)
    episodes, start = [], 0
    for k, (rows, end) in enumerate(fx.meta["rollout_chunks"]):
        rows_k = slice(start, start + rows)
        episodes.append(SingleAgentEpisode(
            observations=[*i["obs"][rows_k], i["rollout/last_obs"][k]],
            infos=[{"cost": 0.0}] + [{"cost": float(c)} for c in i["rollout/cost"][rows_k]],
            actions=list(i["act"][rows_k]), rewards=list(i["rollout/reward"][rows_k]),
            terminated=end == "terminated", truncated=end == "time_limit",
            extra_model_outputs={Columns.ACTION_DIST_INPUTS: list(dist_inputs[rows_k]),
                                 Columns.ACTION_LOGP: list(i["logp"][rows_k])},
            len_lookback_buffer=0, observation_space=spaces.observation_space, action_space=spaces.action_space,
        ).to_numpy())
        start += rows
    return episodes


def connector_step(config_cls, fx: Fixture, preset=None, **fields) -> dict:
    """The learner connector's batch of the fixture's rollout (RLlib's phantom row per chunk and
    its GAE of the rewards, then the family's cost GAE, which standardises A^R and centres A^C over
    the real rows: cost_gae.py), its real rows under the names of OmniSafe's buffer: ``buffer/*``.
    On a learner of its own holding the fixture's weights in float32: RLlib's connector hands the
    module float32 tensors whatever the episodes hold (as in training)."""
    learner = build_on_policy(config_cls, fx, preset, **fields)
    learner.module[DEFAULT_MODULE_ID].unwrapped().float()
    batch = learner._learner_connector(rl_module=learner.module, batch={}, episodes=rollout_episodes(fx),
                                       shared_data={}, metrics=learner.metrics)[DEFAULT_MODULE_ID]
    real = np.asarray(batch[Columns.LOSS_MASK], bool)
    columns = {"adv_r": Postprocessing.ADVANTAGES, "adv_c": COST_ADVANTAGES,
               "target_value_r": Postprocessing.VALUE_TARGETS, "target_value_c": COST_VALUE_TARGETS}
    return {f"buffer/{name}": np.asarray(batch[column], np.float64)[real] for name, column in columns.items()}


def on_policy_step(config_cls, fx: Fixture, preset=None, **fields) -> dict:
    """The fixture's step taken by the project's learner; its outputs under the reference's names:
    ``nu``, ``loss_pi`` (the policy's whole loss, a penalty term included), the critics' losses
    (MSE + critic_l2·Σθ² of that critic, as OmniSafe logs them), ``grad/*`` and ``after/*``."""
    learner = build_on_policy(config_cls, fx, preset, **fields)
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    config = learner.config.get_config_for_module(DEFAULT_MODULE_ID)
    reverse = {v: k for k, v in OMNISAFE_ON_POLICY.items()}
    buffered = connector_step(config_cls, fx, preset, **fields) if "rollout/reward" in fx.inputs else {}
    l2 = {net: config.critic_l2 * sum(float((p.detach() ** 2).sum()) for n, p in module.named_parameters()
                                      if ours(n, reverse).startswith(net)) for net in ("reward_critic", "cost_critic")}
    nu = multiplier_step(learner, fx)
    grads = minibatch_step(learner, on_policy_batch(fx))
    peek = lambda key: float(torch.as_tensor(learner.metrics.peek((DEFAULT_MODULE_ID, key))).detach())  # noqa: E731
    out = {"nu": nu, "loss_pi": peek(POLICY_LOSS_KEY),
           "loss_reward_critic": peek(VF_LOSS_KEY) + l2["reward_critic"],
           "loss_cost_critic": peek(COST_VF_LOSS) + l2["cost_critic"]}
    out.update({f"grad/{ours(n, reverse)}": g.numpy() for n, g in grads.items()})
    out.update({f"after/{ours(n, reverse)}": p.detach().numpy() for n, p in module.named_parameters()})
    return {**out, **buffered}
