"""The registry reads what each algorithm declares in its folder (budgets' sizes, the plan's rate,
the learner keys its rows report, its overrides per task family), and gives an algorithm that
declares none of them the defaults: the service names no algorithm."""

import sys
import types

import pytest

from lac_rllib.algorithms import registry
from lac_rllib.constrained import metrics
from lac_rllib.constrained.task_config import SafeTaskConfig


def test_each_algorithm_declares_its_budget_sizes_in_its_folder():
    assert registry.budget_fields("lac", "quick", "tiny")["langevin_steps"] == 20
    assert registry.budget_fields("lac", "quick", "safety_gym")["actor_hidden"] == (64, 64)  # "*": any other
    assert registry.budget_fields("ppo_lag", "smoke", "mujoco")["num_epochs"] == 2
    assert registry.budget_fields("sac_lag", "quick", "tiny") == {}  # its tiny preset is the quick budget
    assert registry.budget_fields("lac", "paper", "safety_gym") == {}  # the paper's budget: the presets


def test_the_plan_rate_is_the_algorithm_s_own():
    lac = [registry.plan_update_s("lac", {"langevin_steps": t}, "safety_gym") for t in (10, 50)]
    assert lac[1] == pytest.approx(5 * lac[0]) and lac[0] > 0  # the chain grows with T
    sac = [registry.plan_update_s("sac_lag", {"updates_per_env_step": u}, "tiny") for u in (1.0, 2.0)]
    assert sac[1] == pytest.approx(2 * sac[0])


def test_each_algorithm_reports_its_own_learner_keys():
    assert set(metrics.CHAIN_HEALTH_KEYS) <= set(registry.reported_keys("lac"))
    assert not set(metrics.CHAIN_HEALTH_KEYS) & set(registry.reported_keys("ppo_lag"))
    assert set(metrics.PPO_LAG_KEYS) == set(registry.reported_keys("ppo_lag"))
    learner = {metrics.LANGEVIN_AT_BOUND: 0.2, metrics.POLICY_LOSS: 1.5, "num_module_steps_trained": 7}
    result = {**{k: 1.0 for k in metrics.TOP_LEVEL_KEYS}, "training_iteration": 3,
              metrics.LEARNER_RESULTS: {metrics.DEFAULT_MODULE_ID: learner}}
    lac_row = metrics.iteration_row(result, registry.reported_keys("lac"))
    ppo_row = metrics.iteration_row(result, registry.reported_keys("ppo_lag"))
    assert metrics.LANGEVIN_AT_BOUND in lac_row and metrics.POLICY_LOSS not in lac_row
    assert metrics.POLICY_LOSS in ppo_row and metrics.LANGEVIN_AT_BOUND not in ppo_row
    assert "num_module_steps_trained" not in lac_row and lac_row[metrics.ITERATION] == 3


def test_only_lac_sets_fields_per_task_family():
    from lac_rllib.algorithms.lac.config import LACConfig
    from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig

    assert LACConfig().task("SafetyPointButton1-v0").langevin_steps == 50
    assert PPOLagConfig.TASK_FAMILY_OVERRIDES == {}


def test_an_algorithm_that_declares_nothing_gets_the_defaults(monkeypatch):
    bare = types.ModuleType("bare_algo_config")

    class BareConfig(SafeTaskConfig):
        pass

    bare.CONFIG_CLASS = BareConfig
    monkeypatch.setitem(sys.modules, "bare_algo_config", bare)
    monkeypatch.setitem(registry.ALGOS, "bare", "bare_algo_config")
    assert registry.budget_fields("bare", "smoke", "tiny") == {}
    assert registry.plan_update_s("bare", {}, "tiny") == 0.0
    assert registry.reported_keys("bare") == ()
    assert "bare" in registry.algos_text()
