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


def keys(algo):
    return registry.algo_config(algo).REPORTED_KEYS


def test_each_algorithm_reports_its_own_learner_keys():
    assert set(metrics.CHAIN_HEALTH_KEYS) <= set(keys("lac"))
    assert not set(metrics.CHAIN_HEALTH_KEYS) & set(keys("ppo_lag"))
    assert set(metrics.PPO_LAG_KEYS) == set(keys("ppo_lag"))
    learner = {metrics.LANGEVIN_AT_BOUND: 0.2, metrics.POLICY_LOSS: 1.5, "num_module_steps_trained": 7}
    result = {**{k: 1.0 for k in metrics.TOP_LEVEL_KEYS}, "training_iteration": 3,
              metrics.LEARNER_RESULTS: {metrics.DEFAULT_MODULE_ID: learner}}
    lac_row = metrics.iteration_row(result, keys("lac"))
    ppo_row = metrics.iteration_row(result, keys("ppo_lag"))
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

    bare.BareConfig = BareConfig
    monkeypatch.setitem(sys.modules, "bare_algo_config", bare)
    monkeypatch.setitem(registry.ALGOS, "bare", "bare_algo_config.BareConfig")
    assert registry.budget_fields("bare", "smoke", "tiny") == {}
    assert registry.plan_update_s("bare", {}, "tiny") == 0.0
    assert registry.warmup_env_steps("bare", {"x": 1}) == 0 and registry.actions("bare") == ("generator",)
    assert keys("bare") == () and registry.speed_fields("bare") == frozenset()
    assert "bare" in registry.algos_text()


def test_declarations_are_inherited_as_python_inherits_them():
    """An algorithm on another declares only what differs: FOCOPS's speed fields and actions are
    PPO-Lag's object, CUP's plan rate its own; houses are read off the config classes."""
    assert registry.algo_config("focops").SPEED_FIELDS is registry.algo_config("ppo_lag").SPEED_FIELDS
    assert registry.plan_update_s("cup", {}, "tiny") == 2 * registry.plan_update_s("ppo_lag", {}, "tiny")
    houses = {a: registry.house(a) for a in registry.ALGOS}
    assert houses == {"lac": None, "ppo_lag": None, "sac_lag": None, "focops": "ppo_lag", "cup": "ppo_lag",
                      "p3o": None, "respo": "ppo_lag", "trpo_lag": None, "cpo": None, "pcpo": "cpo"}
    assert all(registry.algo_config(a).ALGO == a for a in registry.ALGOS)


# ---------------------------------------------------------------- a user's own algorithm (tests/algorithms/toy_algo.py)
TOY = "tests.algorithms.toy_algo"
REPO = str(__import__("pathlib").Path(__file__).resolve().parents[2])


def test_a_users_algorithm_is_named_by_its_import_path_and_read_like_the_package_s(monkeypatch):
    monkeypatch.syspath_prepend(REPO)
    assert registry.check_algo(TOY) == TOY and not registry.is_builtin(TOY)
    assert registry.algo_config(TOY).__name__ == "ToyConfig" and registry.algo_config(TOY).ALGO == TOY
    # Its own sizes at the smoke budget, its own reported key, the defaults where it declares nothing.
    assert registry.budget_fields(TOY, "smoke", "tiny")["hidden"] == (16, 16)
    assert registry.budget_fields("ppo_lag", "smoke", "tiny")["hidden"] == (32, 32)
    assert keys(TOY)[-1] == "toy_marker" and "toy_marker" not in keys("ppo_lag")
    # What it does not declare it inherits from its house, PPO-Lag.
    assert registry.plan_update_s(TOY, {}, "tiny") == registry.plan_update_s("ppo_lag", {}, "tiny") > 0
    assert registry.speed_fields(TOY) == registry.speed_fields("ppo_lag")
    assert registry.warmup_env_steps(TOY, {"train_batch_size_per_learner": 400}) == 800
    config = registry.build_config(TOY, "lac/PointHazard-v0", 0, {"toy_marker": 2.5}, timesteps=2000)
    assert config.params()["toy_marker"] == 2.5 and config.ALGO == TOY and registry.house(TOY) == "ppo_lag"
    assert registry.parse_sets(TOY, ["toy_marker=3.0"]) == {"toy_marker": 3.0}
    assert registry.module_dir(TOY) == REPO and registry.module_dir("lac") is None  # where trials import it from


ALGO_MODULES = {
    "empty_algo": ("X = 1\n", "algo empty_algo: its module must define one config class named 'empty_algo' (ALGO); "
                   "found none"),
    # PPO-Lag's config imported as it is: it names itself ppo_lag, so every checkpoint would.
    "borrowed_algo": ("from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig  # noqa\n",
                      "algo borrowed_algo: its module must define one config class named 'borrowed_algo' (ALGO); "
                      "found none"),
    "renamed_algo": ("from lac_rllib.algorithms.ppo_lag.config import PPOLagConfig\n"
                     "class MyConfig(PPOLagConfig):\n    ALGO = 'ppo_lag'\n",
                     "found MyConfig (ALGO 'ppo_lag')"),
    "learnerless_algo": ("from lac_rllib.constrained.task_config import SafeTaskConfig\n"
                         "class MyConfig(SafeTaskConfig):\n    pass\n",
                         "algo learnerless_algo: MyConfig declares no FIELDS, LEARNER_CLASS, ALGORITHM_CLASS"),
    "broken_algo": ("raise RuntimeError('needs a GPU')\n",
                    "algo broken_algo: cannot be imported (RuntimeError: needs a GPU)"),
    "needy_algo": ("import not_installed_dependency\n",
                   "algo needy_algo: cannot be imported (ModuleNotFoundError: No module named "
                   "'not_installed_dependency')"),
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


def test_a_users_module_is_announced_before_its_code_runs(tmp_path, monkeypatch, capsys):
    """A slow or hanging import is the user's code, said first: the CLI is never silent before Ray."""
    (tmp_path / "chatty_algo.py").write_text("import sys\nprint('module body runs', file=sys.stderr)\n")
    monkeypatch.setattr(sys, "path", list(sys.path))
    with pytest.raises(ValueError):  # it defines no config class: refused after the import
        registry.check_algo("chatty_algo", (str(tmp_path),))
    err = capsys.readouterr().err
    assert "lac-rllib: importing your algorithm's module chatty_algo" in err
    assert err.index("importing your algorithm's module chatty_algo") < err.index("module body runs")
    sys.modules.pop("chatty_algo", None)
