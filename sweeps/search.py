"""How a search draws its configurations: the searcher's random start, and the Optuna sampler the
sweep builds (sweeps/sweep.py ``search_algorithm``).

A searcher that learns draws its first configurations at random and steers the later ones by the
results in so far. Optuna 5.1's TPE draws its first ``n_startup_trials`` at random (default 10,
``optuna/samplers/_tpe/sampler.py``) and NSGA-II its first generation (``population_size``,
default 50): at those defaults a search of 8 samples never leaves its random start, and "8 TPE
samples" are random search. The sweep sets the start itself (:func:`random_start`): half of the
samples (rounded down), at most Optuna's default, at least one (NSGA-II: two, the parents its
crossover needs). A TPE search of two samples or more then steers at least half of its draws; a
search of 20 or more keeps Optuna's own start. A tuned comparison refuses a TPE search in which no
draw could be steered (sweeps/sweep_file.py ``TuneSpec``). The plan prints both numbers before Ray
starts (:func:`search_text`).

TPE steers a draw toward its "good" trials, the best ⌈n/10⌉ of the n finished (Optuna's γ): one
trial until 11 have finished. On the synthetic test (tests/sweeps/test_search.py) its draws after a
start of 4 were then no closer to the optimum than random ones (mean distance 0.44 against 0.51);
with two good trials they were (0.28). The sweep's γ (:func:`good_trials`) keeps at least two good
trials from 4 finished on, and is Optuna's own from 11 on.

A draw is steered by the configurations that have *finished* when it is made: while several
configurations train at once, a draw made after the start may still see fewer results than the
start (it is then random as well). :func:`steered` estimates this from the trials at a time.
"""

from __future__ import annotations

import math
import threading
import warnings

import optuna

#: Optuna's own random start: ``TPESampler(n_startup_trials=10)``, ``NSGAIISampler(population_size=50)``.
TPE_STARTUP, NSGA2_POPULATION = 10, 50
#: The searchers that steer their draws by the results in so far, and how the plan names them.
LEARNING = {"tpe": "TPE", "motpe": "multi-objective TPE", "nsga2": "NSGA-II"}


def random_start(searcher: str, num_samples: int) -> int | None:
    """How many of a search's ``num_samples`` draws come from its searcher's random start: the
    ``n_startup_trials`` the sweep gives TPE (``tpe``, ``motpe``), the first generation of NSGA-II
    (its ``population_size``: generation 0 is drawn at random), all of them for ``random``;
    None for ``grid`` (nothing is drawn)."""
    if searcher == "grid":
        return None
    if searcher == "random":
        return num_samples
    return min(num_samples, startup_size(searcher, num_samples))


def startup_size(searcher: str, num_samples: int) -> int:
    """The sampler's own parameter: TPE's ``n_startup_trials``, NSGA-II's ``population_size``."""
    half = num_samples // 2
    if searcher == "nsga2":
        return min(NSGA2_POPULATION, max(2, half))
    if searcher in LEARNING:
        return min(TPE_STARTUP, max(1, half))
    raise ValueError(f"searcher {searcher!r} has no random start to size; accepted: {', '.join(LEARNING)}")


def configurations_at_once(trials_at_once: int, seeds: int) -> int:
    """About how many configurations train at once with ``trials_at_once`` trials of ``seeds`` seeds
    each: Tune fills the free trial slots in order, so the next configuration is drawn while the
    last one's seeds still run (1 where trials run one at a time)."""
    return 1 + math.ceil((max(1, trials_at_once) - 1) / max(1, seeds))


def steered(searcher: str, num_samples: int, at_once: int = 1) -> int:
    """How many draws the searcher steers: those after its random start, less the draws made while
    the start's results are still out (``at_once`` configurations training together: draw k sees
    about k − at_once + 1 finished). Exact for configurations run one at a time; 0 for random and grid."""
    if searcher not in LEARNING:
        return 0
    return max(0, num_samples - random_start(searcher, num_samples) - (max(1, at_once) - 1))


def search_text(searcher: str, num_samples: int, at_once: int = 1) -> str:
    """The plan's line on how the samples are drawn, e.g. "8 samples: 4 from TPE's random start,
    4 steered by TPE"."""
    if searcher == "random":
        return f"{num_samples} samples, all at random (Optuna's random sampler)"
    name, start = LEARNING[searcher], random_start(searcher, num_samples)
    first = ("from NSGA-II's first generation (random)" if searcher == "nsga2" else f"from {name}'s random start")
    text = f"{num_samples} samples: {start} {first}, {num_samples - start} steered by {name}"
    now = steered(searcher, num_samples, at_once)
    if now < num_samples - start:
        text += (f" once {start} {'has' if start == 1 else 'have'} finished (with ~{at_once} configurations "
                 f"training at once, about {now}; fewer at once, max_concurrent, steer more)")
    return text


def good_trials(n: int) -> int:
    """TPE's γ for one objective: Optuna's ``default_gamma`` (the best ⌈n/10⌉ of ``n`` finished
    trials, at most 25), at least two from 4 finished on (at most half of them)."""
    return max(min(math.ceil(0.1 * n), 25), min(2, n // 2))


def good_trials_multiobjective(n: int) -> int:
    """TPE's γ for two objectives: Optuna's ``default_gamma_multiobjective`` (⌈n/10⌉), at least two
    from 4 finished on."""
    return max(math.ceil(0.1 * n), min(2, n // 2))


class PicklableNSGAIISampler(optuna.samplers.NSGAIISampler):
    """Optuna 5.1's NSGA-II sampler holds a ``threading.Lock`` (its generation cache), which
    Tune cannot pickle into the experiment state the Tuner writes at once (docs/dependencies.md,
    "Optuna's NSGA-II and Tune's pickling"): the lock is left out and a new one made on load."""

    def __getstate__(self):
        state = self.__dict__.copy()
        state.pop("_thread_lock", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._thread_lock = threading.Lock()


def make_sampler(searcher: str, num_samples: int, seed: int | None) -> optuna.samplers.BaseSampler:
    """The Optuna sampler of a search of ``num_samples`` configurations, seeded, with the random start
    of :func:`random_start` (TPE also with the good trials of :func:`good_trials`). TPE and NSGA-II
    read each trial's feasibility constraint from the trial itself (``trial.set_constraint``, which
    sweeps/sweep.py ``ConstrainedOptunaSearch`` calls): a violated constraint ranks a configuration
    below every feasible one, infeasible ones by their violation. Random ignores it."""
    if searcher == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if searcher == "nsga2":
        return PicklableNSGAIISampler(population_size=startup_size(searcher, num_samples), seed=seed)
    if searcher in LEARNING:
        gamma = good_trials_multiobjective if searcher == "motpe" else good_trials
        with warnings.catch_warnings():  # Optuna 5 deprecates ``gamma`` for its 6.0 (pyproject pins optuna < 6)
            warnings.filterwarnings("ignore", message=".*`gamma`", category=FutureWarning)
            return optuna.samplers.TPESampler(n_startup_trials=startup_size(searcher, num_samples), gamma=gamma,
                                              seed=seed)
    raise ValueError(f"searcher {searcher!r} samples nothing; accepted: random, {', '.join(LEARNING)}")


#: What a configuration's seeds spent in all, told to the searcher with its result (sweeps/sweep.py
#: SeedRepeater): the env steps of each seed's last result, summed (where ASHA stopped it, or its budget).
SPENT = "env_steps_spent"
