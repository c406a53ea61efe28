"""Modules that moved, importable by their old names: a checkpoint pickles its classes by module
path (an RLModule's class, for one), so one written before a move must still find them after it.

``install()`` (run by ``import lac_rllib``) adds a finder to ``sys.meta_path`` that answers an old
name with the module at its new place, the same module object under both names. Add a line to
:data:`MOVED` whenever a module a checkpoint can name moves.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

#: Old module path → where it lives now (the family bases left lac_rllib/constrained/ for
#: lac_rllib/families/, and CPO's episode lengths for its own folder).
MOVED = {
    "lac_rllib.constrained.on_policy_config": "lac_rllib.families.on_policy.config",
    "lac_rllib.constrained.on_policy_learner": "lac_rllib.families.on_policy.learner",
    "lac_rllib.constrained.on_policy_module": "lac_rllib.families.on_policy.module",
    "lac_rllib.constrained.on_policy": "lac_rllib.families.on_policy.algorithm",
    "lac_rllib.constrained.cost_gae": "lac_rllib.families.on_policy.cost_gae",
    "lac_rllib.constrained.lagrangian_learner": "lac_rllib.families.on_policy.lagrangian",
    "lac_rllib.constrained.optim": "lac_rllib.families.on_policy.optim",
    "lac_rllib.constrained.projection": "lac_rllib.families.on_policy.projection",
    "lac_rllib.constrained.trust_region_config": "lac_rllib.families.trust_region.config",
    "lac_rllib.constrained.trust_region_learner": "lac_rllib.families.trust_region.learner",
    "lac_rllib.constrained.trust_region": "lac_rllib.families.trust_region.step",
    "lac_rllib.constrained.off_policy_config": "lac_rllib.families.off_policy.config",
    "lac_rllib.constrained.off_policy": "lac_rllib.families.off_policy.algorithm",
    "lac_rllib.constrained.actor_critic_module": "lac_rllib.families.off_policy.module",
    "lac_rllib.constrained.episode_lengths": "lac_rllib.algorithms.cpo.episode_lengths",
}


class _Loader(importlib.abc.Loader):
    def create_module(self, spec):
        return importlib.import_module(MOVED[spec.name])  # the module itself, not a copy

    def exec_module(self, module) -> None:
        pass  # executed where it lives


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds an old module path of :data:`MOVED` (and nothing else)."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, _Loader())


def install() -> None:
    """Once per process: later calls find the finder there."""
    if not any(isinstance(f, MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedModuleFinder())
