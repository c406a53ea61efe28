"""A cost limit of 0 works for every algorithm (omnisafe#384 reports NaN at ``cost_limit=0``): no
step divides by the limit. Two smoke-sized iterations on the tiny task, whose hazard costs, so the
constraint is violated from the first episode: every loss the row reports, ν and every weight of
the module stay finite, and ν stays ≥ 0."""

import math

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID

from lac_rllib.algorithms import registry
from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, NU, iteration_row

TASK = "lac/PointHazard-v0"


@pytest.mark.parametrize("algo", list(registry.ALGOS))
def test_a_zero_cost_limit_trains_with_finite_losses_and_nu(ray_session, algo):
    sets = {**registry.budget_fields(algo, "smoke", "tiny"), "cost_limit": 0.0}
    config = registry.build_config(algo, TASK, 0, sets, timesteps=10_000)
    algo_obj = config.build_algo()
    try:
        rows = [iteration_row(algo_obj.train(), type(config).REPORTED_KEYS) for _ in range(2)]
        module = algo_obj.learner_group._learner.module[DEFAULT_MODULE_ID]
        tensors = dict(module.named_parameters()) | dict(module.named_buffers())
    finally:
        algo_obj.stop()
    last = rows[-1]
    assert last[COST_LIMIT] == 0.0 and math.isfinite(last[EPISODE_COST])
    assert math.isfinite(last[NU]) and last[NU] >= 0.0, last
    reported = {k: last[k] for k in type(config).REPORTED_KEYS if k in last}
    assert reported, f"{algo} reported none of its keys"
    assert all(math.isfinite(v) for v in reported.values() if isinstance(v, float)), reported
    bad = [name for name, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]
    assert not bad, bad
