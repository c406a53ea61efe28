"""How a search draws its configurations (sweeps/search.py): the searcher's random start, the sampler
the sweep builds, and that its TPE steers its draws after the start, on a synthetic objective with a
constraint, driven through an Optuna study as the sweep tells it (no Ray)."""

import inspect
import math

import numpy as np
import optuna
import pytest

from sweeps import run as cli
from sweeps.objective import objective
from sweeps.search import (
    NSGA2_POPULATION,
    TPE_STARTUP,
    configurations_at_once,
    good_trials,
    good_trials_multiobjective,
    make_sampler,
    random_start,
    search_text,
    steered,
)

SPACE = {"x": optuna.distributions.FloatDistribution(0.0, 1.0), "y": optuna.distributions.FloatDistribution(0.0, 1.0)}
SEEDS = range(16)


def test_the_start_replaces_optunas_defaults_as_installed():
    """The defaults the rule replaces are the installed Optuna's, and the sweep's γ is Optuna's own
    except that it keeps two good trials from 4 finished to 10."""
    from optuna.samplers._tpe.sampler import default_gamma, default_gamma_multiobjective

    assert inspect.signature(optuna.samplers.TPESampler).parameters["n_startup_trials"].default == TPE_STARTUP == 10
    assert inspect.signature(optuna.samplers.NSGAIISampler).parameters["population_size"].default == NSGA2_POPULATION
    differ = [n for n in range(500) if good_trials(n) != default_gamma(n)]
    assert differ == list(range(4, 11)) and {good_trials(n) for n in differ} == {2}
    assert [n for n in range(500) if good_trials_multiobjective(n) != default_gamma_multiobjective(n)] == differ


@pytest.mark.parametrize("searcher,n,start", [
    ("tpe", 1, 1), ("tpe", 2, 1), ("tpe", 3, 1), ("tpe", 8, 4), ("tpe", 19, 9), ("tpe", 20, 10), ("tpe", 200, 10),
    ("motpe", 8, 4), ("nsga2", 2, 2), ("nsga2", 3, 2), ("nsga2", 8, 4), ("nsga2", 1000, 50),
    ("random", 8, 8), ("grid", 8, None),
])
def test_the_random_start_is_half_the_samples_at_most_optunas_own(searcher, n, start):
    assert random_start(searcher, n) == start
    if searcher == "grid":
        return
    sampler = make_sampler(searcher, n, 0)
    if searcher in ("tpe", "motpe"):  # the sampler runs the start the plan prints
        assert sampler._n_startup_trials == start and sampler._gamma is not None
    elif searcher == "nsga2":
        assert sampler.population_size == start
    assert steered(searcher, n) == (0 if searcher == "random" else n - start)


def test_configurations_at_once_and_the_draws_they_leave_unsteered():
    assert [configurations_at_once(c, 3) for c in (1, 2, 3, 4, 6, 16)] == [1, 2, 2, 2, 3, 6]
    assert steered("tpe", 8) == 4 and steered("tpe", 8, at_once=2) == 3 and steered("tpe", 8, at_once=6) == 0
    assert search_text("tpe", 8) == "8 samples: 4 from TPE's random start, 4 steered by TPE"
    assert search_text("tpe", 8, 2).startswith("8 samples: 4 from TPE's random start, 4 steered by TPE once 4 "
                                               "have finished (with ~2 configurations training at once, about 3;")
    assert search_text("random", 8) == "8 samples, all at random (Optuna's random sampler)"
    assert search_text("nsga2", 8) == "8 samples: 4 from NSGA-II's first generation (random), 4 steered by NSGA-II"


def _plan_text(tmp_path, capsys, searcher, concurrent, seeds=1):
    (tmp_path / "s.yaml").write_text(f"budget: smoke\nseeds: {seeds}\nnum_samples: 8\nsearcher: {searcher}\n"
                                     f"max_concurrent: {concurrent}\nsearch: {{beta: {{uniform: [0.0, 20.0]}}}}\n")
    plan, = cli.make_plan(cli.parse_args(["--config", str(tmp_path / "s.yaml"), "--experiment", "test",
                                          "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}",
                                          "--storage", str(tmp_path / "rr"), "--name", f"{searcher}{concurrent}"]))
    capsys.readouterr()
    cli.print_plan(plan)
    return capsys.readouterr().out


def test_the_plan_says_how_many_draws_the_searcher_steers(tmp_path, capsys):
    one_at_a_time = _plan_text(tmp_path, capsys, "tpe", 1)
    assert "  search: 8 samples: 4 from TPE's random start, 4 steered by TPE\n" in one_at_a_time
    # 4 trials at a time of 2 seeds: about 3 configurations at once, the two drawn beside the 4th unsteered
    assert "4 steered by TPE once 4 have finished (with ~3 configurations training at once, about 2;" in \
        _plan_text(tmp_path, capsys, "tpe", 4, seeds=2)
    assert "  search: 8 samples, all at random" in _plan_text(tmp_path, capsys, "random", 1)


def _draws(sampler, f, tell_constraint=True, fold=True, n=8):
    """``n`` draws of ``sampler`` on ``f`` (x, y → return, cost, limit), each told before the next is
    drawn (configurations one at a time), as the sweep tells Optuna a configuration: the objective
    that ranks infeasible below feasible by violation (``fold``; else the return alone, as a
    multi-objective study's values hold no limit) and the constraint cost − limit."""
    study = optuna.create_study(direction="maximize", sampler=sampler)
    out = []
    for _ in range(n):
        trial = study.ask(SPACE)
        x, y = trial.params["x"], trial.params["y"]
        ret, cost, limit = f(x, y)
        if tell_constraint:
            trial.set_constraint("episode_cost_minus_limit", cost - limit)
        study.tell(trial, objective(ret, cost, limit) if fold else ret)
        out.append((x, y))
    return np.array(out)


def _after_start(make, f, **kw) -> np.ndarray:
    """Every seed's draws after the sweep's random start of an 8-sample TPE search, stacked."""
    start = random_start("tpe", 8)
    return np.concatenate([_draws(make(seed), f, **kw)[start:] for seed in SEEDS])


def _distance(points, optimum) -> float:
    return float(np.mean(np.hypot(points[:, 0] - optimum[0], points[:, 1] - optimum[1])))


def _default_gamma_tpe(seed):  # the sweep's start, Optuna's γ: one good trial until 11 have finished
    return optuna.samplers.TPESampler(n_startup_trials=random_start("tpe", 8), seed=seed)


def test_tpe_steers_its_draws_after_the_start_to_the_feasible_optimum():
    """Maximise −(x−0.7)² − (y−0.2)² on [0, 1]² subject to x + y ≤ 1.2: the draws of an 8-sample
    search after its random start lie closer to the optimum (0.7, 0.2) than random draws, by a
    bound that the search as it was built before (Optuna's default start of 10: all 8 random) and
    one with Optuna's γ (one good trial) both cross."""
    def f(x, y):
        return -(x - 0.7) ** 2 - (y - 0.2) ** 2, x + y, 1.2

    optimum = (0.7, 0.2)
    rand = _distance(_after_start(lambda s: optuna.samplers.RandomSampler(seed=s), f), optimum)
    bound = 0.7 * rand
    tpe = _distance(_after_start(lambda s: make_sampler("tpe", 8, s), f), optimum)
    assert tpe < bound, (tpe, rand)
    before = _distance(_after_start(lambda s: optuna.samplers.TPESampler(seed=s), f), optimum)
    one_good = _distance(_after_start(_default_gamma_tpe, f), optimum)
    assert before >= bound and one_good >= bound, (before, one_good, bound)
    # the figures sweeps/search.py and docs/sweeps.md quote
    assert (round(one_good, 2), round(rand, 2), round(tpe, 2)) == (0.44, 0.51, 0.28)


def test_tpe_reads_the_constraint_it_is_told():
    """Maximise −(x−0.9)² − (y−0.9)² subject to x + y ≤ 1: the unconstrained optimum is infeasible.
    Told the return alone and the constraint, most of the draws after the start are feasible; the
    same sampler not told the constraint chases the infeasible corner, and random draws are
    feasible half the time: both cross the bound."""
    def f(x, y):
        return -(x - 0.9) ** 2 - (y - 0.9) ** 2, x + y, 1.0

    def feasible(points):
        return float(np.mean(points.sum(axis=1) <= 1.0))

    told = feasible(_after_start(lambda s: make_sampler("tpe", 8, s), f, fold=False))
    blind = feasible(_after_start(lambda s: make_sampler("tpe", 8, s), f, fold=False, tell_constraint=False))
    rand = feasible(_after_start(lambda s: optuna.samplers.RandomSampler(seed=s), f, fold=False))
    assert told >= 0.65 > max(blind, rand), (told, blind, rand)
    assert math.isclose(rand, 0.5, abs_tol=0.1)
    assert (round(told, 2), round(blind, 2)) == (0.77, 0.09)  # the figures docs/sweeps.md quotes


def test_an_env_step_budget_draws_while_a_whole_configuration_fits_and_an_early_stop_frees_its_rest():
    """sweeps/sweep.py EnvStepBudget inside the seeds' repeater: 2 seeds × 1,000 env steps per
    configuration, 5,000 in all. Two configurations run at once (4,000 committed); a third would pass
    the budget, so the search waits (None), and once one stops early at 500 + 500 (1,000 spent)
    the third is drawn; the search is finished only when no configuration fits and none runs. Its
    counts go through Tune's wrapper state."""
    from ray.tune.search import Searcher

    from sweeps.search import SPENT
    from sweeps.sweep import EnvStepBudget, SeedRepeater

    class Draws(Searcher):
        def __init__(self):
            super().__init__(metric="objective", mode="max")
            self.n, self.told = 0, []

        def suggest(self, trial_id):
            self.n += 1
            return {"x": self.n}

        def on_trial_complete(self, trial_id, result=None, error=False):
            self.told.append((trial_id, result, error))

    inner = Draws()
    budget = EnvStepBudget(inner, budget=5_000, per_configuration=2_000)
    search = SeedRepeater(budget, repeat=2)
    first = [search.suggest(f"a{i}") for i in range(2)] + [search.suggest(f"b{i}") for i in range(2)]
    assert [c["x"] for c in first] == [1, 1, 2, 2]
    assert search.suggest("c0") is None, "a third configuration would pass the budget while two run"

    def finish(trial_id, steps, ret=1.0):
        search.on_trial_result(trial_id, {"env_steps": steps})
        search.on_trial_complete(trial_id, {"env_steps": steps, "episode_return": ret, "episode_cost": 0.0,
                                            "cost_limit": 1.0})

    finish("a0", 500)
    finish("a1", 500)  # configuration 1 stopped early: 1,000 spent, 2,000 still committed to configuration 2
    assert inner.told[-1][1][SPENT] == 1_000 and budget.spent == 1_000
    third = search.suggest("c0")
    assert third["x"] == 3 and search.suggest("c1")["x"] == 3
    assert search.suggest("d0") is None  # 1,000 + 2 × 2,000 committed: a fourth would pass 5,000
    again = EnvStepBudget(Draws(), budget=5_000, per_configuration=2_000)
    again.set_state(budget.get_state())  # what Tune's SearchGenerator saves of a wrapper and restores
    assert again.spent == 1_000 and again.live == budget.live
    for t in ("b0", "b1", "c0", "c1"):
        finish(t, 1_000)
    assert budget.spent == 5_000 and not budget.live
    assert search.suggest("e0") == Searcher.FINISHED
