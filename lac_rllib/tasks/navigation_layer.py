"""Safety-Gymnasium's navigation task layer as array operations over N envs at once.

Each function is the batched form of one piece of safety_gymnasium 1.0.0's per-env Python
(``safety_gymnasium/bases/base_task.py``, ``bases/base_agent.py``, ``assets/geoms/*``,
``assets/free_geoms/*``), written so that every value it returns equals the stock one bit for bit:
the same float operations in the same order, never a shortcut that rounds differently. Where an
equivalent formula would round otherwise it is named (tests/tasks/test_batched_navigation.py pins
each choice against the stock expression on random inputs):

- the egocentric vector is ``np.matmul`` of the world vector with the agent's ``xmat``, as
  ``BaseTask._ego_xy`` does; ``np.einsum`` or a written-out sum differ in the last bit (numpy's
  matmul kernel, not a left-to-right sum);
- a lidar distance is ``np.abs`` of the complex number ``x + iy``, as ``_obs_lidar_pseudo`` does;
  ``np.hypot(x, y)`` differs by one ulp on some inputs;
- an XY distance is ``sqrt(dx² + dy²)``, ``BaseAgent.dist_xy``'s ``sqrt(sum(square(d)))`` written
  out: numpy sums two terms as ``0 + dx² + dy²``, which rounds as ``dx² + dy²``.
"""

from __future__ import annotations

import functools

import numpy as np


def ego_xy(points: np.ndarray, agent_pos: np.ndarray, agent_mat: np.ndarray) -> np.ndarray:
    """(N, K, 2) egocentric XY of ``points`` (N, K, 2 or 3; z ignored) seen from the agent at
    ``agent_pos`` (N, 3) with rotation ``agent_mat`` (N, 3, 3): ``BaseTask._ego_xy``
    (``matmul([x, y, 0] − agent_pos, agent_mat)[:2]``) for every point of every env."""
    world = np.zeros(points.shape[:2] + (3,))
    world[..., :2] = points[..., :2]
    world -= agent_pos[:, None, :]
    return np.matmul(world, agent_mat)[..., :2]


def pseudo_lidar(ego: np.ndarray, num_bins: int, max_dist: float | None, exp_gain: float,
                 alias: bool) -> np.ndarray:
    """(N, num_bins) lidar of the objects at egocentric ``ego`` (N, K, 2): each bin reads the
    closeness of its nearest object, with aliasing into the neighbouring bins
    (``BaseTask._obs_lidar_pseudo``)."""
    return pseudo_lidars(ego, [slice(0, ego.shape[1])], num_bins, max_dist, exp_gain, alias)[0]


def pseudo_lidars(ego: np.ndarray, groups: list[slice], num_bins: int, max_dist: float | None, exp_gain: float,
                  alias: bool) -> list[np.ndarray]:
    """One (N, num_bins) lidar per group of objects (``groups``: slices of ``ego``'s K objects),
    every object's distance, angle and bin computed in one pass. A bin is the max over the readings
    its objects write there (its own bin's and, aliased, its neighbours'): exact in any order, so
    taken over one one-hot array (N, readings, bins) with the readings of each group side by side
    (one ``reduceat`` at the groups' starts) rather than written object by object."""
    z = ego[..., 0] + 1j * ego[..., 1]
    dist = np.abs(z)
    angle = np.angle(z) % (np.pi * 2)
    bin_size = (np.pi * 2) / num_bins
    bins = (angle / bin_size).astype(np.int64)  # int() of a non-negative float: truncation
    if max_dist is None:
        sensor = np.exp(-exp_gain * dist)
    else:
        sensor = np.maximum(0, max_dist - dist) / max_dist
    where, value = [bins], [sensor]
    if alias:
        frac = (angle - bin_size * bins) / bin_size
        where += [(bins + 1) % num_bins, (bins - 1) % num_bins]
        value += [frac * sensor, (1 - frac) * sensor]
    n, k, r = ego.shape[0], ego.shape[1], len(where)
    filled = [g for g in groups if g.stop > g.start]
    out = {}
    if filled:
        columns, starts = _gather(k, r, tuple((g.start, g.stop) for g in filled))
        b, v = np.concatenate(where, axis=1)[:, columns], np.concatenate(value, axis=1)[:, columns]
        one_hot = np.where(b[..., None] == np.arange(num_bins), v[..., None], 0.0)
        best = np.maximum.reduceat(one_hot, starts, axis=1)
        out = {id(g): best[:, i] for i, g in enumerate(filled)}
    return [out[id(g)] if id(g) in out else np.zeros((n, num_bins)) for g in groups]


@functools.lru_cache(maxsize=64)
def _gather(k: int, r: int, spans: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Reading j of object i sits at column j·K + i of the readings side by side: each group's
    columns gathered together, and where each group starts (the same every step of a task)."""
    columns = np.concatenate([np.arange(a, b) + j * k for a, b in spans for j in range(r)])
    return columns, np.cumsum([0] + [(b - a) * r for a, b in spans[:-1]])


def dist_xy(points: np.ndarray, agent_pos: np.ndarray) -> np.ndarray:
    """(N, K) XY distances from the agent (N, 3) to ``points`` (N, K, 2 or 3): ``BaseAgent.dist_xy``,
    ``sqrt(sum(square(d)))``; a sum of two squares is ``dx² + dy²`` in any form, written out."""
    dx = points[..., 0] - agent_pos[:, None, 0]
    dy = points[..., 1] - agent_pos[:, None, 1]
    return np.sqrt(dx * dx + dy * dy)


def hazard_violation(dist: np.ndarray, size: float) -> np.ndarray:
    """(N,) whether any hazard costs this step: ``Hazards.cal_cost`` adds ``cost · (size − dist)``
    for each hazard with ``dist <= size``, and the indicator (``constrain_indicator``) is that sum
    > 0, i.e. some ``dist < size``."""
    return (size - dist > 0).any(axis=-1)


def clip_reward(reward: np.ndarray, clip: float | None) -> np.ndarray:
    """``Builder._reward``'s last resort: a reward outside (−clip, clip) is clipped (within, and at
    ±clip itself, clipping returns the same value, so one ``np.clip`` is the stock rule)."""
    return np.clip(reward, -clip, clip) if clip else reward
