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
    every reading of every env and group goes into one flat (N, groups, bins) array by one
    ``np.maximum.at``, rather than object by object."""
    z = ego[..., 0] + 1j * ego[..., 1]
    dist = np.abs(z)
    angle = np.arctan2(z.imag, z.real) % (np.pi * 2)  # np.angle(z), as its own code computes it
    bin_size = (np.pi * 2) / num_bins
    bins = (angle / bin_size).astype(np.int64)  # int() of a non-negative float: truncation
    if max_dist is None:
        sensor = np.exp(-exp_gain * dist)
    else:
        sensor = np.maximum(0, max_dist - dist) / max_dist
    n, k = ego.shape[:2]
    first = _first_bins(n, k, tuple((g.start, g.stop) for g in groups), num_bins)
    if alias:
        frac = (angle - bin_size * bins) / bin_size
        where = np.concatenate([first + bins, first + (bins + 1) % num_bins, first + (bins - 1) % num_bins], axis=None)
        value = np.concatenate([sensor, frac * sensor, (1 - frac) * sensor], axis=None)
    else:
        where, value = (first + bins).ravel(), sensor.ravel()
    out = np.zeros((n, len(groups) + 1, num_bins))  # the last: the readings of objects in no group
    np.maximum.at(out.reshape(-1), where, value)
    return [out[:, i] for i in range(len(groups))]


@functools.lru_cache(maxsize=64)
def _first_bins(n: int, k: int, spans: tuple, num_bins: int) -> np.ndarray:
    """(N, K): where object i of env e writes in the flat (N, groups + 1, bins) output, its bin 0;
    an object in no group writes in the last, unread (the same every step of a task)."""
    group = np.full(k, len(spans), np.int64)
    for g, (a, b) in enumerate(spans):
        group[a:b] = g
    return (np.arange(n)[:, None] * (len(spans) + 1) + group) * num_bins


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
