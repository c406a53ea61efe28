"""Which random streams a trial's seed gives, and the fresh seeds of a confirmation.

A trial of seed ``s`` does not draw from one stream but from several integers near ``s`` (the
installed RLlib 2.60 and gymnasium 1.2):

- env runner ``w`` (0: the driver's; 1..R: the remote ones) seeds random, numpy and torch with
  ``s + w`` (ray/rllib/env/env_runner.py:90-102, ``self.config.seed + (self.worker_index or 0)``),
  and so does the random-action space (lac_rllib/constrained/costs.py ``on_environment_created``);
- its first reset passes that seed to its vector env (ray/rllib/env/single_agent_env_runner.py:799,
  ``seed=self._seed if self._needs_initial_reset else None``), which resets sub-env ``i`` with
  ``s + w + i`` (gymnasium/vector/sync_vector_env.py:185-186, ``[seed + i for i in range(...)]``);
  the driver's runner makes envs only when there are no remote ones (single_agent_env_runner.py:98-104);
- the algorithm and its learner seed torch with ``s`` (ray/rllib/algorithms/algorithm.py:738,
  ray/rllib/core/learner/learner.py:243), as do the off-policy row draws (``ShuffleRows``, ``DrawRows``);
- the evaluation block resets episode ``j`` and seeds torch with ``eval_seed(s) + j`` (lac_rllib/evaluation.py).

So seeds ``s`` and ``s + 1`` share all but one of their training streams: a confirmation on the
seeds after the search's largest (3, 4, ... after 0-2) reran, with 10 envs per runner, 9 of seed 3's
10 env streams that the search trained on. Seeds that differ in the integer are not fresh.

The scheme: every trial's training streams lie in ``[s, s + STRIDE)`` (``STRIDE`` above any
runners + envs a trial uses; a trial past it is refused, :func:`check_streams`), so a fresh seed
``STRIDE`` or more past the search's largest shares no stream with any search seed, and fresh seeds
``STRIDE`` apart share none with each other. Fresh seed ``k`` is ``B + k * STRIDE``, ``B`` the first
multiple of ``STRIDE`` at or above ``max(search) + STRIDE`` (search seeds 0-2: 2000, 3000, ...):
round numbers say at a glance that a run is a confirmation. The bound, not a trial's own runners
and envs, sets ``B``: the confirmation is planned without the search's resolved runners (its CPUs
per trial may differ), and the bound holds for any. Search seeds do not change, so seeded search
runs repeat exactly.

The evaluation block's seeds (:func:`eval_seed`) stay as they were (a search's evaluation repeats):
``EVAL_SEED_BASE + EVAL_BLOCK * s`` on, a block per seed holding the most episodes a sweep may ask
for, far above the training streams of seeds below ``EVAL_SEED_BASE - STRIDE``; :func:`fresh_seeds`
checks the actual intervals, and refuses fresh seeds whose training or evaluation streams meet the
search's.

Not covered: a trial restored from a checkpoint reseeds from a hash of (seed, iteration)
(lac_rllib/constrained/algorithm.py ``resume_seed``): its streams differ from the search's with
overwhelming probability, not by construction. RLlib's evaluation env runners (+1e6) are not used.
"""

from __future__ import annotations

import bisect

from sweeps.sweep_file import MAX_SEED

#: Training streams a seed may use: ``[seed, seed + STRIDE)``. Far above the runners + envs of any
#: trial (PointGoal1's: 10 envs), small enough for 1,000 confirmation seeds below ``EVAL_SEED_BASE``.
STRIDE = 1_000
#: The evaluation block's env seeds start here, ``EVAL_BLOCK`` per trial seed.
EVAL_SEED_BASE = 2**30
#: Evaluation seeds per trial seed: the most ``eval_episodes`` a sweep file accepts (sweep_file.py).
EVAL_BLOCK = 1_000


def eval_seed(seed: int) -> int:
    """The first env seed of the evaluation block of a trial of ``seed`` (its episode i: + i)."""
    return EVAL_SEED_BASE + EVAL_BLOCK * int(seed)


def env_seeds(seed: int, env_runners: int, envs_per_runner: int) -> set[int]:
    """The seeds RLlib resets a trial's envs with (the module docstring's rule): sub-env ``i`` of
    runner ``w`` gets ``seed + w + i``; the runners are 1..R, or the driver's (0) without remote ones."""
    runners = range(1, env_runners + 1) if env_runners else (0,)
    return {int(seed) + w + i for w in runners for i in range(envs_per_runner)}


def check_streams(env_runners: int, envs_per_runner: int) -> None:
    """Refuse a trial whose training streams reach ``seed + STRIDE``: its streams could meet a
    confirmation's (fresh seeds are ``STRIDE`` apart)."""
    if env_runners + envs_per_runner > STRIDE:
        raise ValueError(f"num_env_runners {env_runners} + num_envs_per_env_runner {envs_per_runner}: the envs are "
                         f"seeded up to seed + {env_runners + envs_per_runner - 1}, past the seed stride {STRIDE} that "
                         f"keeps a confirmation's streams apart from its search's (sweeps/seeds.py); accepted: "
                         f"num_env_runners + num_envs_per_env_runner <= {STRIDE}")


def fresh_seeds(search_seeds, count: int) -> tuple[int, ...]:
    """``count`` confirmation seeds none of whose streams (training or evaluation) any of
    ``search_seeds`` drew from: ``B``, ``B + STRIDE``, ... (the module docstring's scheme)."""
    if count < 1:
        return ()
    top = max(int(s) for s in search_seeds)
    first = -(-(top + STRIDE) // STRIDE) * STRIDE  # the first multiple of STRIDE at or above top + STRIDE
    fresh = tuple(first + k * STRIDE for k in range(count))
    if fresh[-1] > MAX_SEED:
        raise ValueError(f"{count} fresh seeds from {first}, {STRIDE} apart, pass {MAX_SEED} (search seeds up to "
                         f"{top}); accepted: fewer confirmation seeds or smaller search seeds")
    _check_apart(search_seeds, fresh)
    return fresh


def seeds_text(seeds) -> str:
    """Seeds as a plan prints them: ``1000, 2000, ..., 5000``."""
    seeds = [int(s) for s in seeds]
    return ", ".join(map(str, seeds)) if len(seeds) <= 3 else f"{seeds[0]}, {seeds[1]}, ..., {seeds[-1]}"


def _intervals(seeds) -> list[tuple[int, int]]:
    """Each seed's training bound ``[s, s + STRIDE)`` and evaluation block, as closed intervals."""
    return [iv for s in seeds for iv in ((int(s), int(s) + STRIDE - 1),
                                         (eval_seed(s), eval_seed(s) + EVAL_BLOCK - 1))]


def _merged(intervals) -> list[tuple[int, int]]:
    """Closed intervals merged into disjoint ones, in order."""
    out = []
    for lo, hi in sorted(intervals):
        if out and lo <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], hi))
        else:
            out.append((lo, hi))
    return out


def _check_apart(search_seeds, fresh) -> None:
    """A ValueError naming the first fresh seed whose streams meet a search seed's."""
    search = _merged(_intervals(search_seeds))
    starts = [lo for lo, _ in search]
    for f in fresh:
        for lo, hi in _intervals([f]):
            k = bisect.bisect_right(starts, hi) - 1  # the last search interval starting at or before hi
            if k >= 0 and search[k][1] >= lo:
                raise ValueError(f"fresh seed {f}'s streams {lo}..{hi} meet the search seeds' {search[k][0]}.."
                                 f"{search[k][1]} (training within {STRIDE} of a seed, evaluation from "
                                 f"{EVAL_SEED_BASE}: sweeps/seeds.py); accepted: search seeds whose fresh seeds' "
                                 f"training stays below the evaluation seeds ({EVAL_SEED_BASE})")
