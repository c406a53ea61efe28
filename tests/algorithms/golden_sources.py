"""Golden steps recorded from a paper's own source (benchmarks/golden/focops_authors.py,
respo_authors.py), whose networks name their parameters otherwise than OmniSafe's: golden.py's
harness with a name map per reference, and outputs in the reference's names *and shapes* (their
log σ may be (1, act_dim) where the project's is (act_dim,))."""

from __future__ import annotations

import torch
from ray.rllib.core import DEFAULT_MODULE_ID

from tests.algorithms.golden import Fixture, Spaces, ours

# ymzhang01/focops models.py (GaussianPolicy, Value) -> the project's RLModule (ppo_lag/module.py).
FOCOPS_AUTHORS = {
    "policy.mlp_net.0": "encoder.actor_encoder.net.mlp.0", "policy.mlp_net.2": "encoder.actor_encoder.net.mlp.2",
    "policy.mean_layer": "pi.net.mlp.0", "policy.logstd_layer": "pi.log_std",
    "value_net.mlp_net.0": "encoder.critic_encoder.net.mlp.0",
    "value_net.mlp_net.2": "encoder.critic_encoder.net.mlp.2", "value_net.v_head": "vf.net.mlp.0",
    "cvalue_net.mlp_net.0": "cost_vf.encoder.net.mlp.0", "cvalue_net.mlp_net.2": "cost_vf.encoder.net.mlp.2",
    "cvalue_net.v_head": "cost_vf.head.net.mlp.0",
}

# milanganai.github.io NeurIPS2023/code/core_respo.py (MLPActorCritic: pi, v, vc, vp) -> respo/module.py.
RESPO_AUTHORS = {
    "pi.log_std": "pi.log_std",
    "pi.mu_net.0": "encoder.actor_encoder.net.mlp.0", "pi.mu_net.2": "encoder.actor_encoder.net.mlp.2",
    "pi.mu_net.4": "pi.net.mlp.0",
    "v.v_net.0": "encoder.critic_encoder.net.mlp.0", "v.v_net.2": "encoder.critic_encoder.net.mlp.2",
    "v.v_net.4": "vf.net.mlp.0",
    "vc.v_net.0": "cost_vf.encoder.net.mlp.0", "vc.v_net.2": "cost_vf.encoder.net.mlp.2",
    "vc.v_net.4": "cost_vf.head.net.mlp.0",
    "vp.v_net.0": "reach_vf.encoder.net.mlp.0", "vp.v_net.2": "reach_vf.encoder.net.mlp.2",
    "vp.v_net.4": "reach_vf.head.net.mlp.0",
}


def build(config_cls, fx: Fixture, mapping: dict, preset=None, **fields):
    """The project's learner on the fixture's spaces, networks and float64 starting weights (as
    golden.build_on_policy, with ``mapping`` from the reference's names to the module's)."""
    obs_dim, act_dim = fx.inputs["obs"].shape[1], fx.inputs["act"].shape[1]
    config = (config_cls().task(fx.meta["task"], **({"preset": preset} if preset else {}))
              .training(hidden=tuple(fx.meta["hidden"]), obs_normalization=False, **fields))
    learner = config.build_learner(env=Spaces(obs_dim, act_dim))
    params = dict(learner.module[DEFAULT_MODULE_ID].unwrapped().named_parameters())
    for name, value in fx.before.items():
        p = params[ours(name, mapping)]
        p.data = torch.as_tensor(value, dtype=torch.float64).reshape(p.shape).clone()
    learner.reports_minibatch = True
    return learner


def in_reference_names(learner, grads: dict, mapping: dict, fx: Fixture) -> dict:
    """``grad/*`` (the gradients each optimizer stepped on) and ``after/*`` (the parameters after
    the step) under the reference's names, each in the shape the reference holds it."""
    reverse = {v: k for k, v in mapping.items()}
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    out = {}
    for prefix, named in (("grad", grads), ("after", {n: p.detach() for n, p in module.named_parameters()})):
        for name, value in named.items():
            theirs = ours(name, reverse)
            out[f"{prefix}/{theirs}"] = value.numpy().reshape(fx.before[theirs].shape)
    return out


def critic_l2(learner, mapping: dict, net: str) -> float:
    """critic_l2·Σθ² over the reference's network ``net`` before the step: the term the reference
    adds to that critic's logged loss (the project's metric is the MSE alone)."""
    config = learner.config.get_config_for_module(DEFAULT_MODULE_ID)
    reverse = {v: k for k, v in mapping.items()}
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    return config.critic_l2 * sum(float((p.detach() ** 2).sum()) for n, p in module.named_parameters()
                                  if ours(n, reverse).startswith(net + "."))
