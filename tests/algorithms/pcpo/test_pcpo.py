"""PCPO: its defaults, and its learner's projection on a real batch (RLlib's own env runner sampling
lac/PointHazard-v0 with the learner's policy, in this process: no Ray): from an infeasible θ_old
the paper's KL projection puts the step on the linearised constraint's boundary, c + bᵀΔ = 0,
with b the gradient of the cost surrogate computed here with torch's own Normal; feasible, it is
the reward's TRPO step."""

import copy
import math

import pytest
import torch
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

from lac_rllib.algorithms.cpo.config import COST_GAP
from lac_rllib.algorithms.pcpo import config as C
from lac_rllib.algorithms.pcpo import learner as L
from lac_rllib.constrained.metrics import NU, TS_EPISODE_COSTS
from lac_rllib.families.on_policy.cost_gae import COST_ADVANTAGES
from lac_rllib.tasks import get_task

TASK = "lac/PointHazard-v0"  # cost limit 2, action (2,)


def test_defaults_are_omnisafes():
    config = C.PCPOConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert (config.projection, config.backtrack_iters, config.target_kl, config.cg_iters, config.cost_gap_scale) == \
        ("omnisafe", 200, 0.01, 15, "none")
    assert "cpo_case" not in C.PCPOConfig.REPORTED_KEYS
    docs = C.PCPOConfig.FIELDS.docs()
    assert set(docs) == C.PCPOConfig.FIELDS.names and all(docs.values()) and set(C.PRESETS) == set(C.PRESET_NAMES)


def update(monkeypatch, cost_gap: float):
    """One update of a PCPO Learner with the paper's projection, (8, 8) networks and CG run to
    convergence (so gᵀH⁻¹b = bᵀH⁻¹g), Ĵ_C = b + ``cost_gap``: the reported values, the policy before,
    the whole batch, and the line search's full step Δθ with pcpo_step's x = H⁻¹g and q."""
    config = C.PCPOConfig().task(TASK).training(
        total_env_steps=10_000, train_batch_size_per_learner=400, num_envs_per_env_runner=1, minibatch_size=100,
        num_epochs=1, cost_window=None, target_kl=0.01, projection="kl", hidden=(8, 8), cg_iters=300).debugging(seed=0)
    lrn = config.build_learner(env=get_task(TASK).make())
    runner = SingleAgentEnvRunner(config=config, worker_index=0)
    module = lrn.module[DEFAULT_MODULE_ID].unwrapped()
    runner.set_state({COMPONENT_RL_MODULE: {DEFAULT_MODULE_ID: module.get_state(inference_only=True)}})
    episodes, old, seen = runner.sample(num_timesteps=400, random_actions=False), copy.deepcopy(module), {}
    search, pcpo_step = L.CPOTorchLearner.search, L.pcpo_step
    monkeypatch.setattr(L.CPOTorchLearner, "search",
                        lambda self, policy, step, *a: seen.update(step=step) or search(self, policy, step, *a))
    monkeypatch.setattr(L, "pcpo_step", lambda g, b, x, p, c, max_kl, **k: seen.update(x=x, q=k["q"]) or
                        pcpo_step(g, b, x, p, c, max_kl, **k))
    results = lrn.update(episodes=episodes, timesteps={TS_EPISODE_COSTS: [2.0 + cost_gap]}, minibatch_size=100,
                         num_epochs=1)
    out = {k: float(v.peek()) for k, v in results[DEFAULT_MODULE_ID].items() if not isinstance(v, dict)}
    return out, old, lrn.cost_gae.last_batch[DEFAULT_MODULE_ID], seen


def cost_gradient(module, whole) -> torch.Tensor:
    """b = ∇ mean r·A^C over the real rows at θ_old, with torch.distributions.Normal."""
    params = [*module.encoder.actor_encoder.parameters(), *module.pi.parameters()]
    mean, log_std = module.action_dist_inputs(whole[Columns.OBS]).chunk(2, dim=-1)
    logp = torch.distributions.Normal(mean, log_std.exp()).log_prob(whole[Columns.ACTIONS]).sum(-1)
    ratio = torch.exp(logp - whole[Columns.ACTION_LOGP])
    surrogate = (ratio * whole[COST_ADVANTAGES])[whole[Columns.LOSS_MASK]].mean()
    return torch.cat([g.reshape(-1) for g in torch.autograd.grad(surrogate, params)])


def test_the_kl_projection_lands_on_the_linearised_boundary_when_infeasible(monkeypatch):
    c = 0.05  # above the limit, by less than the reward's step can undo: the projection binds
    out, old, whole, seen = update(monkeypatch, c)
    b, step = cost_gradient(old, whole), seen["step"]
    assert out[COST_GAP] == pytest.approx(c) and out[NU] > 0
    assert float(b @ step) + c == pytest.approx(0.0, abs=1e-4 * c)


def test_feasible_it_is_the_reward_s_trpo_step(monkeypatch):
    out, _, _, seen = update(monkeypatch, -100.0)
    assert out[NU] == 0.0 and out[COST_GAP] == -100.0
    torch.testing.assert_close(seen["step"], math.sqrt(2 * 0.02 / seen["q"]) * seen["x"])  # δ = 2·0.01
