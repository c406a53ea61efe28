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


# ---------------------------------------------------------------- a user's own algorithm (tests/algorithms/toy_algo.py)
TOY = "tests.algorithms.toy_algo"
REPO = str(__import__("pathlib").Path(__file__).resolve().parents[2])


def test_every_algorithm_exposes_the_names_a_users_module_must():
    for algo in registry.ALGOS:
        assert [n for n in registry.REQUIRED if not hasattr(registry.algo_config(algo), n)] == [], algo


def test_a_users_algorithm_is_named_by_its_import_path_and_read_like_the_package_s(monkeypatch):
    monkeypatch.syspath_prepend(REPO)
    assert registry.check_algo(TOY) == TOY and not registry.is_builtin(TOY)
    assert registry.algo_config(TOY).__name__ == TOY
    # Its own sizes at the smoke budget, its own reported key, the defaults where it declares nothing.
    assert registry.budget_fields(TOY, "smoke", "tiny")["hidden"] == (16, 16)
    assert registry.budget_fields("ppo_lag", "smoke", "tiny")["hidden"] == (32, 32)
    assert registry.reported_keys(TOY)[-1] == "toy_marker" and "toy_marker" not in registry.reported_keys("ppo_lag")
    # What it does not declare it takes from its house, PPO-Lag (registry.declared).
    assert registry.plan_update_s(TOY, {}, "tiny") == registry.plan_update_s("ppo_lag", {}, "tiny") > 0
    assert registry.speed_fields(TOY) == registry.speed_fields("ppo_lag")
    assert registry.warmup_env_steps(TOY, {"train_batch_size_per_learner": 400}) == 800
    config = registry.build_config(TOY, "lac/PointHazard-v0", 0, {"toy_marker": 2.5}, timesteps=2000)
    assert config.params()["toy_marker"] == 2.5 and config.algo_class.ALGO == TOY
    assert registry.parse_sets(TOY, ["toy_marker=3.0"]) == {"toy_marker": 3.0}
    assert registry.module_dir(TOY) == REPO and registry.module_dir("lac") is None  # where trials import it from


ALGO_MODULES = {
    "half_algo": ("CONFIG_CLASS = object\nACTIONS = ('generator',)\n",
                  "algo half_algo: its module lacks PARAMS, FIELDS, PRESETS; accepted: "
                  "a module exposing CONFIG_CLASS, PARAMS"),
    # An algorithm of its own (no house to take them from) that does not say how it acts.
    "orphan_algo": ("from ray.rllib.algorithms.algorithm import Algorithm\n"
                    "from ray.rllib.algorithms.algorithm_config import AlgorithmConfig\n"
                    "class OrphanAlgo(Algorithm):\n    ALGO = 'orphan_algo'\n"
                    "class OrphanConfig(AlgorithmConfig):\n"
                    "    ALGORITHM_CLASS = 'orphan_algo.OrphanAlgo'\n"
                    "    def __init__(self):\n        super().__init__(algo_class=OrphanAlgo)\n"
                    "CONFIG_CLASS, PARAMS, FIELDS, PRESETS = OrphanConfig, None, None, {}\n",
                    "algo orphan_algo: neither its module nor the algorithm it extends declares SPEED_FIELDS, "
                    "ACTIONS; accepted: a module exposing CONFIG_CLASS, PARAMS, FIELDS, PRESETS, SPEED_FIELDS, "
                    "ACTIONS"),
    "broken_algo": ("raise RuntimeError('needs a GPU')\n",
                    "algo broken_algo: cannot be imported (RuntimeError: needs a GPU)"),
    "needy_algo": ("import not_installed_dependency\n",
                   "algo needy_algo: cannot be imported (ModuleNotFoundError: No module named "
                   "'not_installed_dependency')"),
    # PPO-Lag's names re-exported as they are: its algorithm would call itself ppo_lag in every checkpoint.
    "borrowed_algo": ("from lac_rllib.algorithms.ppo_lag.config import *  # noqa\n"
                      "from lac_rllib.algorithms.ppo_lag.config import CONFIG_CLASS, PARAMS, FIELDS, PRESETS\n",
                      "algo borrowed_algo: its algorithm PPOLag names itself 'ppo_lag' (ALGO); accepted: "
                      "ALGO = 'borrowed_algo'"),
    "nowhere.algo": (None, f"unknown algo 'nowhere.algo'; accepted: {registry.algos_text()}, or the import path of "
                           "your own algorithm's module (no module 'nowhere' on the Python path nor"),
    "my-algo": (None, f"unknown algo 'my-algo'; accepted: {registry.algos_text()}, or the import path"),
}


@pytest.mark.parametrize("name", ALGO_MODULES)
def test_a_users_module_that_cannot_run_is_one_line_naming_it(tmp_path, monkeypatch, name):
    """Found beside the sweep file (a search dir), checked before anything is built."""
    source, needle = ALGO_MODULES[name]
    if source is not None:
        (tmp_path / f"{name}.py").write_text(source)
    monkeypatch.setattr(sys, "path", list(sys.path))  # the search dir it adds goes with the test
    with pytest.raises(ValueError) as e:
        registry.check_algo(name, (str(tmp_path),))
    assert needle in str(e.value) and "\n" not in str(e.value), str(e.value)
    assert name not in registry._USER  # refused: checked again next time, not remembered
