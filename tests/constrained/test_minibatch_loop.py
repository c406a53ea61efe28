"""constrained/minibatch_loop.py: the fused loop walks RLlib's minibatches, row for row."""

import numpy as np
import pytest
import torch
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.minibatch_utils import MiniBatchCyclicIterator

from lac_rllib.constrained.minibatch_loop import (
    TS_MINIBATCHES,
    cyclic_minibatch_indices,
    gathered_minibatches,
    update_kwargs,
)


@pytest.mark.parametrize("n, size, epochs, shuffle, total", [
    (2020, 64, 40, True, 0),   # PPO-Lag's OmniSafe preset: minibatches straddle the epochs' ends
    (2000, 250, 10, True, 0),  # the tiny preset: 8 minibatches an epoch, a minibatch ends on the last row
    (500, 256, 2, True, 100),  # SAC-Lag's shuffled passes: a count of minibatches over a small buffer
    (5120, 256, 1, False, 20), # SAC-Lag's draws: one pass in order
    (300, 300, 3, True, 0),    # full-batch epochs
])
def test_the_same_rows_in_the_same_order_as_rllibs_iterator(n, size, epochs, shuffle, total):
    """Each row carries its index; RLlib's iterator (its reshuffles drawing from numpy's global
    RNG) and ours, started from the same seed, give the same minibatches, and the RNG ends in the
    same state."""
    batch = MultiAgentBatch({"m": SampleBatch({"row": np.arange(n)})}, env_steps=n)
    np.random.seed(7)
    theirs = [mb.policy_batches["m"]["row"].copy() for mb in MiniBatchCyclicIterator(
        batch, num_epochs=epochs, minibatch_size=size, shuffle_batch_per_epoch=shuffle,
        num_total_minibatches=total)]
    after_theirs = np.random.random()
    np.random.seed(7)
    ours = [idx["m"] for idx in cyclic_minibatch_indices({"m": n}, minibatch_size=size, num_epochs=epochs,
                                                         shuffle=shuffle, num_total_minibatches=total)]
    assert np.random.random() == after_theirs
    assert len(ours) == len(theirs) > 1
    for a, b in zip(theirs, ours):
        np.testing.assert_array_equal(a, b)
    assert len(np.unique(np.concatenate(ours))) == n  # every row trained


def test_update_kwargs_hand_the_plan_to_the_learner_or_to_rllib():
    fused = update_kwargs("fused", minibatch_size=64, num_epochs=40, shuffle=True)
    assert fused["minibatch_size"] is None and fused["num_epochs"] == 1
    assert fused["timesteps"][TS_MINIBATCHES] == {"minibatch_size": 64, "num_epochs": 40, "shuffle": True,
                                                  "num_total_minibatches": 0}
    rllib = update_kwargs("rllib", minibatch_size=64, num_epochs=40, shuffle=True)
    assert rllib == {"minibatch_size": 64, "num_epochs": 40, "shuffle_batch_per_epoch": True,
                     "num_total_minibatches": 0, "timesteps": {}}
    with pytest.raises(ValueError, match="update_path 'fast'; accepted: fused | rllib"):
        update_kwargs("fast", minibatch_size=64)


def test_an_empty_module_batch_is_refused():
    with pytest.raises(ValueError, match="empty"):
        next(cyclic_minibatch_indices({"m": 0}, minibatch_size=4))
    first, second = cyclic_minibatch_indices({"m": 5}, minibatch_size=4)  # one epoch: 4 rows, then 1 + 3 wrapped
    np.testing.assert_array_equal(first["m"], [0, 1, 2, 3])
    np.testing.assert_array_equal(second["m"], [4, 0, 1, 2])


@pytest.mark.parametrize("chunk", [1, 3, 64])
def test_gathered_minibatches_are_each_minibatchs_own_gather(chunk):
    """A chunk's gather sliced per minibatch equals each minibatch's own index_select, bit for bit,
    contiguous, for every module, across chunk edges and a short last minibatch."""
    gen = torch.Generator().manual_seed(0)
    columns = {"a": {"obs": torch.randn(37, 5, generator=gen), "mask": torch.rand(37, generator=gen) > 0.3},
               "b": {"obs": torch.randn(20, 2, generator=gen)}}
    np.random.seed(0)
    plan = list(cyclic_minibatch_indices({"a": 37, "b": 20}, minibatch_size=8, num_epochs=3, shuffle=True))
    got = list(gathered_minibatches(columns, plan, chunk=chunk))
    assert len(got) == len(plan) == 14
    for mb, indices in zip(got, plan, strict=True):
        for mid, idx in indices.items():
            for k, v in columns[mid].items():
                assert mb[mid][k].is_contiguous() and torch.equal(mb[mid][k], v[torch.from_numpy(idx)])
