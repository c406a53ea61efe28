"""CPO: its defaults and the paper's preset, and its learner on a real batch (RLlib's own env runner
sampling lac/PointHazard-v0 with the learner's policy, in this process: no Ray), the cost gap c
set through the episode costs handed to the update so that the step lands in each case: the case
and ν* it reports, and the step each case takes (the TRPO step, the dual's step inside the
linearised constraint, the recovery along −H⁻¹b), and c divided by the episodes' mean length."""

import copy
import math

import pytest
import torch
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

from lac_rllib.algorithms.cpo import config as C
from lac_rllib.algorithms.cpo import learner as L
from lac_rllib.algorithms.cpo.config import COST_GAP, CPO_CASE
from lac_rllib.constrained.metrics import NU, TS_EPISODE_COSTS
from lac_rllib.families.trust_region.config import LINE_SEARCH_FRACTION
from lac_rllib.tasks import get_task

TASK = "lac/PointHazard-v0"  # cost limit 2, action (2,)
DELTA = 0.02  # target_kl 0.01 per action dimension


def test_defaults_are_omnisafes_and_the_ssa_preset_scales_the_gap():
    config = C.CPOConfig.build("SafetyPointGoal1-v0", 0, {}, timesteps=100_000)
    assert (config.target_kl, config.cg_iters, config.backtrack_iters, config.cost_gap_scale,
            config.dual_convention, config.critic_lr, config.num_epochs, config.minibatch_size) == \
        (0.01, 15, 20, "none", "paper", 1e-3, 10, 128)
    assert not {"nu_init", "lagrangian_lr"} & C.CPOConfig.FIELDS.names  # no multiplier
    ssa = C.CPOConfig.build("SafetyPointGoal1-v0", 0, {"preset": "ssa"}, timesteps=100_000)
    assert (ssa.cost_gap_scale, ssa.cost_window, ssa.backtrack_iters, ssa.cg_iters, ssa.max_kl(2)) == \
        ("episode_length", None, 10, 10, 0.01)
    docs = C.CPOConfig.FIELDS.docs()
    assert set(docs) == C.CPOConfig.FIELDS.names and all(docs.values()) and set(C.PRESETS) == set(C.PRESET_NAMES)


def make(**fields):
    """A CPO Learner (Ĵ_C: this iteration's episode costs, cost_window None), its state, and 400
    steps its policy sampled: 4 episodes of 100 steps (the seed's policy never reaches the goal)."""
    config = C.CPOConfig().task(TASK).training(
        total_env_steps=10_000, train_batch_size_per_learner=400, num_envs_per_env_runner=1, minibatch_size=100,
        num_epochs=1, cost_window=None, target_kl=0.01, **fields).debugging(seed=0)
    lrn = config.build_learner(env=get_task(TASK).make())
    runner = SingleAgentEnvRunner(config=config, worker_index=0)
    runner.set_state({COMPONENT_RL_MODULE: {DEFAULT_MODULE_ID: lrn.module[DEFAULT_MODULE_ID].get_state(
        inference_only=True)}})
    episodes = runner.sample(num_timesteps=400, random_actions=False)
    assert [e.t for e in episodes if e.is_done] == [100] * 4
    return lrn, lrn.get_state(), episodes


@pytest.fixture(scope="module")
def setup():
    return make()


def step_at(setup, monkeypatch, cost_gap: float):
    """One update from the saved state with Ĵ_C = b + ``cost_gap`` (b = 2): the reported values,
    cpo_step's output, and the line search's full step Δθ."""
    lrn, state, episodes = setup
    lrn.set_state(state)
    seen = {}
    cpo_step, search = L.cpo_step, L.TrustRegionTorchLearner.search

    def spy_step(g, b, x, p, c, max_kl, **kwargs):
        seen.update(g=g, b=b, x=x, p=p, c=c, out=cpo_step(g, b, x, p, c, max_kl, **kwargs))
        return seen["out"]

    monkeypatch.setattr(L, "cpo_step", spy_step)
    monkeypatch.setattr(L.TrustRegionTorchLearner, "search",
                        lambda self, policy, step, *a: seen.update(step=step) or search(self, policy, step, *a))
    results = lrn.update(episodes=copy.deepcopy(episodes), timesteps={TS_EPISODE_COSTS: [2.0 + cost_gap]},
                         minibatch_size=100, num_epochs=1)
    return {k: float(v.peek()) for k, v in results[DEFAULT_MODULE_ID].items() if not isinstance(v, dict)}, seen


def test_each_case_its_dual_and_its_step(setup, monkeypatch):
    """c chosen around √(2δ·s), where the boundary of the linearised constraint touches the trust
    region (B = 2δ − c²/s changes sign): case 3 (ν* 0, TRPO's step √(2δ/q)·x), 2 and 1 (the dual's
    step (x − ν*p)/λ*, inside the linearised constraint c + bᵀΔ ≤ 0, on it when ν* > 0), 0 (the
    recovery −√(2δ/s)·p, whose line search lowers the cost surrogate)."""
    out, seen = step_at(setup, monkeypatch, -100.0)
    s, q = float(seen["b"] @ seen["p"]), float(seen["out"].q)
    edge = math.sqrt(2 * DELTA * s)
    assert (out[CPO_CASE], out[NU], out[COST_GAP]) == (3.0, 0.0, -100.0)
    torch.testing.assert_close(seen["step"], math.sqrt(2 * DELTA / q) * seen["x"], rtol=1e-4, atol=1e-7)
    for case, c in ((2, -0.5 * edge), (1, 0.5 * edge)):
        out, seen = step_at(setup, monkeypatch, c)
        result = seen["out"]
        assert out[CPO_CASE] == case and out[NU] == pytest.approx(result.nu) and out[COST_GAP] == pytest.approx(c)
        torch.testing.assert_close(seen["step"], (seen["x"] - result.nu * seen["p"]) / result.lam)
        linearised = c + float(seen["b"] @ seen["step"])
        assert linearised <= 1e-3 * abs(c) and (result.nu == 0 or abs(linearised) <= 1e-3 * abs(c))
    assert result.nu > 0  # case 1: θ_old is infeasible, the constraint binds
    out, seen = step_at(setup, monkeypatch, 2.0 * edge)
    assert (out[CPO_CASE], out[NU]) == (0.0, pytest.approx(math.sqrt(2 * DELTA / s), rel=1e-5))
    torch.testing.assert_close(seen["step"], -out[NU] * seen["p"], rtol=1e-4, atol=1e-7)
    assert out[LINE_SEARCH_FRACTION] > 0  # accepted: the cost surrogate did not rise (c > 0)


def test_the_ssa_scale_divides_the_gap_by_the_mean_episode_length(monkeypatch):
    out, seen = step_at(make(cost_gap_scale="episode_length"), monkeypatch, 3.0)
    assert seen["c"] == pytest.approx(3.0 / 100) and out[COST_GAP] == pytest.approx(0.03)
