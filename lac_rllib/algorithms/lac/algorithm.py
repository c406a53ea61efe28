"""LAC(OffPolicySafeAlgorithm): Algorithm 2 of the paper on RLlib's new API stack.

One ``training_step`` = one iteration k of Algorithm 2:
  1. sample ``env_steps_per_iteration`` steps with the generator π_φ (uniform random actions
     in the first ``random_iterations`` iterations [C]);
  2. store them in the replay buffer (lac_rllib/families/off_policy/algorithm.py);
  3. ν update (eq. 14) from the episodes completed in this batch, inside the Learner, before
  4. one pass of minibatches over the whole buffer in a single ``learner_group.update`` call
     (docs/dependencies.md, "Cost of an update call": each call costs ~0.1 s, so not one call per minibatch).
"""

from __future__ import annotations

import numpy as np
from ray.rllib.utils.annotations import override

from lac_rllib.algorithms.lac.config import LACConfig
from lac_rllib.constrained.metrics import TS_ITERATION, TS_MEAN_EPISODE_COST
from lac_rllib.families.off_policy.algorithm import OffPolicySafeAlgorithm


class LAC(OffPolicySafeAlgorithm):
    ALGO, CONFIG_CLASS = "lac", LACConfig

    @override(OffPolicySafeAlgorithm)
    def training_step(self) -> None:
        cfg = self.config
        returns, costs = self.sample_into_replay(random_actions=self.iteration < cfg.random_iterations)
        n_rows = self.replay_buffer.get_num_timesteps()
        # Ĵ_C of eq. (14): the mean cost of the episodes completed in this batch [C]; with K
        # constraints the K means, one per multiplier.
        if cfg.num_constraints > 1:
            j_c = np.mean(self.constraint_costs, axis=0).tolist() if self.constraint_costs else None
        else:
            j_c = float(np.mean(costs)) if costs else None
        self.update_from_replay(
            minibatch_size=cfg.lac_minibatch_size,
            num_total_minibatches=max(1, int(cfg.gradient_passes * n_rows / cfg.lac_minibatch_size)),
            timesteps={TS_MEAN_EPISODE_COST: j_c, TS_ITERATION: self.iteration},
        )
        self.log_top_level(returns, costs, self.constraint_costs)
