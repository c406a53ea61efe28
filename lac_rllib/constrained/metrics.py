"""Result keys, declared once (as RLlib keeps its own in ``ray/rllib/utils/metrics.py``), and the
per-iteration row that lac-train, the sweep's trainable, the sweep and its report all read.

Four kinds of key, each with its own prefix or place so that no two meanings share a name:
- the top level of every iteration's result (every constrained algorithm reports these);
- the learner's results, per module (``result["learners"][module_id]``);
- what the algorithm hands each learner update in ``timesteps`` (``TS_``);
- what rides in ``episode.custom_data`` from the env runners (``CD_``).
"""

from __future__ import annotations

import math

from ray.air.constants import TRAINING_ITERATION
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.metrics import LEARNER_RESULTS

# ----- Top level of every iteration's result -----
# Means over the episodes completed in the iteration (the last known values carry over an
# iteration in which none completed); the cost summed or discounted per the task's convention.
EPISODE_RETURN, EPISODE_COST = "episode_return", "episode_cost"
COST_LIMIT = "cost_limit"  # b
FEASIBLE = "feasible"  # 1.0 when episode_cost <= cost_limit
NU = "nu"  # the Lagrange multiplier (the learner logs it per module under the same key)
EPISODES_THIS_ITER = "episodes_this_iter"
ENV_STEPS = "env_steps"  # lifetime env steps sampled
# Training-time safety (Eckel et al. 2024): the cost of every episode completed so far (as the task
# counts it) over the env steps sampled so far, and that total itself (its lifetime sum, checkpointed).
COST_RATE, COST_TOTAL = "cost_rate", "cost_total"
#: The top-level values of an iteration's row.
TOP_LEVEL_KEYS = (EPISODE_RETURN, EPISODE_COST, COST_LIMIT, FEASIBLE, NU, ENV_STEPS, COST_RATE)

# ----- Learner results, per module; the last minibatch's value unless noted -----
CRITIC_LOSS, ACTOR_LOSS = "critic_loss", "actor_loss"  # LAC: L_Q (eq. 12), L_A (eqs. 15-16)
ACTOR_NLL, ACTOR_KL = "actor_nll", "actor_kl"  # L_A's terms: −mean log π_φ(ã|s*), mean KL(π_φ ‖ π_φ')
Q_REWARD_MEAN, Q_COST_MEAN = "q_reward_mean", "q_cost_mean"  # mean online Q_R(s, a), Q_C(s, a)
NU_MAX = "nu_max"  # the bound ν was held under this iteration (docs/spec.md §4)
# The iteration's mean critic targets ȳ_R, ȳ_C (they set the next bound).
TARGET_REWARD_MEAN, TARGET_COST_MEAN = "target_reward_mean", "target_cost_mean"
# Chain health (docs/spec.md §1), means over about one iteration's minibatches.
LANGEVIN_ENERGY_DROP = "langevin_energy_drop"  # E(s, ã_0) − E(s, ã_T)
LANGEVIN_DISPLACEMENT = "langevin_displacement"  # ‖ã_T − ã_0‖₂
LANGEVIN_GRAD_NORM = "langevin_grad_norm"  # ‖∇_a E‖₂ per sample, before the clip
LANGEVIN_CLIP_FRACTION = "langevin_clip_fraction"  # fraction of chain steps the clip bound
LANGEVIN_AT_BOUND = "langevin_at_bound"  # fraction of end points ã_T on an action bound
ACTOR_STD_MEAN = "actor_std_mean"  # mean σ of π_φ
CHAIN_HEALTH_KEYS = (LANGEVIN_ENERGY_DROP, LANGEVIN_DISPLACEMENT, LANGEVIN_GRAD_NORM,
                     LANGEVIN_CLIP_FRACTION, LANGEVIN_AT_BOUND, ACTOR_STD_MEAN)
# PPO-Lag (RLlib's PPO keys, then its own).
POLICY_LOSS, VF_LOSS = "policy_loss", "vf_loss"  # RLlib's PPO: the clipped surrogate, the reward critic's MSE
COST_VF_LOSS = "cost_vf_loss"  # masked mean (V_C − target)², last minibatch
COST_WINDOW_MEAN = "cost_window_mean"  # Ĵ_C that ν's step used (NaN: no episode yet); SAC-Lag's too
KL_FULL_BATCH = "kl_full_batch"  # KL(π_old ‖ π) over the batch at the last epoch check
EPOCHS_TRAINED = "epochs_before_kl_stop"  # epochs the policy trained this iteration
PPO_LAG_KEYS = (POLICY_LOSS, VF_LOSS, COST_VF_LOSS, COST_WINDOW_MEAN, KL_FULL_BATCH, EPOCHS_TRAINED)
# An algorithm's own keys are declared in its config (FOCOPS, P3O, CUP, RESPO, CPO), a family's in
# its base's (the trust-region line search: lac_rllib/families/trust_region/config.py).
#: A row's values that must be finite: a NaN here fails the trial (sweeps/trainable.py).
MUST_BE_FINITE = (CRITIC_LOSS, ACTOR_LOSS, NU)

# ----- Handed by the algorithm to every learner update, in ``timesteps`` -----
TS_MEAN_EPISODE_COST = "safe_mean_episode_cost"  # Ĵ_C of eq. (14): the batch's completed episodes; None if none
TS_ITERATION = "safe_training_iteration"  # the algorithm's iteration k (0-based)
TS_EPISODE_COSTS = "safe_episode_costs"  # the baselines: the costs of the episodes completed this iteration
#: With several constraints, what the multipliers read instead: each completed episode's K costs
#: (the on-policy and SAC-Lag windows), and LAC's Ĵ_C as a K-vector in ``TS_MEAN_EPISODE_COST``.
TS_CONSTRAINT_COSTS = "safe_constraint_costs"

# ----- episode.custom_data, accumulated on the env runners (they survive episode chunking) -----
CD_EPISODE_COST, CD_EPISODE_RETURN = "safe_episode_cost", "safe_episode_return"
CD_CONSTRAINT_COSTS = "safe_constraint_costs"  # with several constraints: the episode's cost of each


#: The top-level keys that carry one constraint of several (``episode_cost/NAME``, ``cost_limit/NAME``).
PER_CONSTRAINT_TOP = (f"{EPISODE_COST}/", f"{COST_LIMIT}/")


def per_constraint(key: str, name: str) -> str:
    """A metric's key for one constraint of several (``nu/hazards``, ``episode_cost/vases``)."""
    return f"{key}/{name}"

#: The env runners' metric: the episode cost over the last 100 episodes.
EPISODE_COST_MEAN = "episode_cost_mean"

# ----- The per-iteration row -----
ITERATION = "iteration"  # training_iteration, 1-based as RLlib counts it


def iteration_row(result: dict, reported: tuple[str, ...] = (), module_id: str = DEFAULT_MODULE_ID
                  ) -> dict[str, float]:
    """One iteration's row from ``Algorithm.train()``'s result: the top-level keys, the learner's
    values the algorithm reports (``reported``: its config's ``REPORTED_KEYS``) that it logged this
    iteration, and the iteration. Every value a float (the iteration an int)."""
    row = {k: float(result[k]) for k in TOP_LEVEL_KEYS}
    learner = result.get(LEARNER_RESULTS, {}).get(module_id, {})
    row.update({k: float(learner[k]) for k in reported if k in learner})
    # Several constraints: each one's cost and limit, and its multiplier (``per_constraint`` keys).
    row.update({k: float(v) for k, v in result.items() if k.startswith(PER_CONSTRAINT_TOP)})
    row.update({k: float(v) for k, v in learner.items() if k.startswith(f"{NU}/")})
    row[ITERATION] = int(result[TRAINING_ITERATION])
    return row


def non_finite(row: dict) -> list[str]:
    """The keys of ``MUST_BE_FINITE`` whose value in ``row`` is NaN or infinite."""
    return [k for k in MUST_BE_FINITE if k in row and not math.isfinite(row[k])]
