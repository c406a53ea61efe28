"""A run whose fields change mid-run: what a restore puts back that the new fields must override.

Population-based training (sweeps/pbt.py) and the replay of its schedule change a member's fields
by rebuilding its algorithm with the new values and restoring the saved state into it (the donor's
on an exploit, its own on a replayed change). Everything a config sets at build survives that:
the chain's T, η, λ (LAC's module reads them from its config), β, the clip, the multiplier's rate
(``LagrangeMultiplier.get_state`` saves its rule's moments, not its lr). One thing does not: an
optimizer's ``state_dict`` carries its ``param_groups``' lr, so RLlib's restore hands the new
member the donor's learning rate, and RLlib resets it from the member's own schedule only after
the next update (``Learner.after_gradient_based_update``): that first update would run at the
donor's rate (ray-project/ray#62173 is this class of bug). :func:`reapply_learning_rates` sets each
optimizer's lr from the learner's own schedule at once.
"""

from __future__ import annotations

from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME


def _reapply(learner, timestep: int) -> dict[str, float]:
    """Each optimizer of ``learner`` with an lr schedule at its schedule's value for ``timestep``
    (RLlib keeps the schedules in ``_optimizer_lr_schedules`` and has no public accessor)."""
    out = {}
    for name, optimizer in learner._named_optimizers.items():
        schedule = learner._optimizer_lr_schedules.get(optimizer)
        if schedule is not None:
            lr = float(schedule.update(timestep=timestep))
            learner._set_optimizer_lr(optimizer, lr=lr)
            out[name] = lr
    return out


def reapply_learning_rates(algo) -> list[dict[str, float]]:
    """After ``algo.restore_from_path``: every learner's optimizers at the lr its own config gives at
    the restored env steps; returns optimizer name → lr per learner (what a test compares)."""
    timestep = int(algo.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))
    return _each(algo, lambda learner: _reapply(learner, timestep))


def optimizer_lrs(algo) -> list[dict[str, float]]:
    """Optimizer name → its lr now, per learner."""
    return _each(algo, lambda learner: {name: float(optimizer.param_groups[0]["lr"])
                                        for name, optimizer in learner._named_optimizers.items()})


def _each(algo, func) -> list:
    """``func`` on every learner of ``algo`` (local or remote), its results (an error raised)."""
    return [r.get() for r in algo.learner_group.foreach_learner(func)]
