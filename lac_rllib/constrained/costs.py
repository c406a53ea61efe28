"""Getting the cost signal through RLlib: a learner connector for the per-step cost column,
connectors that shuffle or draw the train batch's rows, and env-runner callbacks for episode costs.

Every task reports a step's cost in ``info["cost"]`` (lac_rllib.tasks). RLlib carries infos in
its episodes; the pieces here turn them into (a) a ``costs`` column aligned row by row with
rewards and next observations, (b) the episode cost Ĵ_C per the task's convention (summed or
discounted with γ_C), which drives ν (eq. 14) and the reported metrics.

A run with ``constraints`` (lac_rllib/tasks/constraints.py) reads each constraint's cost from its
own info keys instead: with one constraint the column and Ĵ_C are that constraint's, shaped as
above; with K > 1 the column is (B, K) and each episode also carries its K costs
(``CD_CONSTRAINT_COSTS``), the vector Ĵ_C of the K multipliers, beside the summed ``info["cost"]``
the reports show.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.utils.annotations import override

from lac_rllib.constrained.metrics import (
    CD_CONSTRAINT_COSTS,
    CD_EPISODE_COST,
    CD_EPISODE_RETURN,
    EPISODE_COST_MEAN,
)
from lac_rllib.tasks.constraints import ConstraintSet

COSTS = "costs"  # the train batch's cost column, row-aligned with rewards


def step_cost(info: dict) -> float:
    try:
        return float(info["cost"])
    except (KeyError, TypeError):
        raise KeyError(
            f"the env's step info has no 'cost' entry (got keys {sorted(info or {})}); "
            "LAC tasks must report the per-step cost in info['cost']"
        ) from None


class AddCostsFromInfos(ConnectorV2):
    """Adds the ``costs`` column: the cost of each transition (s, a, r, c, s').

    It must sit right after ``AddNextObservationsFromEpisodesToTrainBatch`` in an off-policy
    learner pipeline (see docs/dependencies.md, "The cost column": placed earlier, rows come out
    misaligned), and right after ``AddColumnsFromEpisodesToTrainBatch`` in PPO's, which has no next
    observations (tests/algorithms/*/ check the alignment on ``lac/CostProbe-v0``). Infos index like
    observations (index 0 is the reset info), so the cost of step t is ``infos[t + 1]``.

    ``constraints`` (``ConstraintSet.as_data()``; None: ``info["cost"]``): each row's costs of the
    run's constraints, a number with one, a (K,) vector with several.
    """

    def __init__(self, *args, constraints: dict | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._set = None if constraints is None else ConstraintSet.from_data(constraints)

    def row_costs(self, infos) -> np.ndarray:
        """The cost column's rows for ``infos``: (n,), or (n, K) with several constraints."""
        if self._set is None:
            return np.asarray([step_cost(i) for i in infos], dtype=np.float32)
        rows = np.stack([self._set.step_costs(i) for i in infos]) if infos else np.zeros((0, len(self._set)))
        return rows.astype(np.float32)[:, 0] if len(self._set) == 1 else rows.astype(np.float32)

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        if COSTS in batch:
            return batch
        for episode in self.single_agent_episode_iterator(episodes, agents_that_stepped_only=False):
            infos = episode.get_infos(slice(1, len(episode) + 1))
            self.add_n_batch_items(
                batch, COSTS, items_to_add=self.row_costs(infos),
                num_items=len(episode), single_agent_episode=episode,
            )
        return batch


class SelectRows(ConnectorV2):
    """Replaces each module's batched train batch by the rows :meth:`pick` chooses from it, the same
    rows in every column, so a row's observation, action, reward and cost stay together. A batch
    whose columns differ in length is left as it is."""

    # No __init__ here (each subclass seeds its own generator): RLlib records a piece's constructor
    # arguments, to rebuild it from a checkpoint, from the frame of the piece's own __init__.

    def pick(self, n: int) -> np.ndarray:
        """The indices of the rows to keep, in order, from a batch of ``n`` rows."""
        raise NotImplementedError

    @override(ConnectorV2)
    def __call__(self, *, rl_module, batch, episodes, explore=None, shared_data=None, **kwargs) -> Any:
        for module_id, columns in batch.items():
            if not isinstance(columns, dict):
                continue
            n = {len(v) for v in columns.values() if isinstance(v, np.ndarray)}
            if len(n) != 1:
                continue
            idx = self.pick(n.pop())
            batch[module_id] = {k: (v[idx] if isinstance(v, np.ndarray) else v) for k, v in columns.items()}
        return batch


class ShuffleRows(SelectRows):
    """Permutes the rows of the batched train batch (one permutation for all columns).

    Learner.update only shuffles between epochs; LAC makes exactly one pass over the buffer
    per iteration (docs/spec.md §5), so without this the minibatches would be consecutive steps.
    """

    def __init__(self, *args, seed: int | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._rng = np.random.default_rng(seed)

    @override(SelectRows)
    def pick(self, n: int) -> np.ndarray:
        return self._rng.permutation(n)


class DrawRows(SelectRows):
    """Draws ``rows`` rows of the batched train batch uniformly *with* replacement (one index
    array for all columns): each minibatch the learner then cuts from it in order is a uniform
    draw from the buffer, as OmniSafe's ``OffPolicyBuffer.sample_batch`` (``torch.randint``) makes
    one per gradient step. Without it the minibatches are shuffled passes over the buffer
    (:class:`ShuffleRows`), no row drawn twice before every row was drawn once.
    """

    def __init__(self, *args, rows: int, seed: int | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.rows = int(rows)
        self._rng = np.random.default_rng(seed)

    @override(SelectRows)
    def pick(self, n: int) -> np.ndarray:
        return self._rng.integers(0, n, size=self.rows)


class EpisodeCostCallback(RLlibCallback):
    """Accumulates each episode's cost (and return) on the env runner, as the task counts it.

    Ĵ_C = Σ_t γ_C^t c_t with γ_C = ``config.effective_episode_cost_discount`` (1 = a plain sum).
    The totals ride along in ``episode.custom_data`` to the driver, which takes the episodes
    completed in the latest batch for the ν update, and are logged as RLlib env-runner metrics.
    """

    @override(RLlibCallback)
    def on_environment_created(self, *, env_runner, env, **kwargs) -> None:
        # RLlib samples random actions (the first iterations, [C]) from the vector env's action
        # space and never seeds it; seed it like the envs, so a run repeats from config.seed.
        if env_runner.config.seed is not None:
            env.action_space.seed(env_runner.config.seed + env_runner.worker_index)

    #: The run's constraints (None: ``info["cost"]``), read from the runner's config once.
    _constraints: ConstraintSet | None | bool = False

    def constraints(self, env_runner) -> ConstraintSet | None:
        if self._constraints is False:
            self._constraints = env_runner.config.constraint_set
        return self._constraints

    @override(RLlibCallback)
    def on_episode_start(self, *, episode, env_runner, **kwargs) -> None:
        episode.custom_data[CD_EPISODE_COST] = 0.0
        episode.custom_data[CD_EPISODE_RETURN] = 0.0
        constraints = self.constraints(env_runner)
        if constraints is not None and len(constraints) > 1:
            episode.custom_data[CD_CONSTRAINT_COSTS] = np.zeros(len(constraints))

    @override(RLlibCallback)
    def on_episode_step(self, *, episode, env_runner, **kwargs) -> None:
        t = episode.t - 1  # global index of the step just taken
        weight = env_runner.config.effective_episode_cost_discount ** t
        info, constraints = episode.get_infos(-1), self.constraints(env_runner)
        if constraints is None:
            episode.custom_data[CD_EPISODE_COST] += weight * step_cost(info)
        elif len(constraints) == 1:  # the one constraint's cost, as info["cost"] otherwise
            episode.custom_data[CD_EPISODE_COST] += weight * float(constraints.step_costs(info)[0])
        else:  # each constraint's (its multiplier's Ĵ_C), and the summed cost the reports show
            episode.custom_data[CD_CONSTRAINT_COSTS] += weight * constraints.step_costs(info)
            episode.custom_data[CD_EPISODE_COST] += weight * step_cost(info)
        episode.custom_data[CD_EPISODE_RETURN] += float(episode.get_rewards(-1))

    @override(RLlibCallback)
    def on_episode_end(self, *, episode, metrics_logger, **kwargs) -> None:
        metrics_logger.log_value(EPISODE_COST_MEAN, episode.custom_data[CD_EPISODE_COST], window=100)


def completed_episode_stats(episodes) -> tuple[list[float], list[float]]:
    """(returns, costs) of the episodes that ended in ``episodes`` (chunks from one sample)."""
    done = [e for e in episodes if e.is_done and CD_EPISODE_COST in e.custom_data]
    return ([e.custom_data[CD_EPISODE_RETURN] for e in done], [e.custom_data[CD_EPISODE_COST] for e in done])


def completed_constraint_costs(episodes) -> list[list[float]]:
    """Each constraint's cost of the episodes that ended in ``episodes`` (a K-list per episode, in
    the order of :func:`completed_episode_stats`); empty where the run has one constraint."""
    return [[float(c) for c in e.custom_data[CD_CONSTRAINT_COSTS]] for e in episodes
            if e.is_done and CD_EPISODE_COST in e.custom_data and CD_CONSTRAINT_COSTS in e.custom_data]
