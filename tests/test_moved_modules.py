"""lac_rllib.moved_modules: a module that moved is importable by its old name, as the same module,
so that a checkpoint pickled before the move (its RLModule's class by module path) restores."""

import importlib
import pickle

import pytest

from lac_rllib.moved_modules import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_module_name_is_the_module_at_its_new_place(old):
    assert importlib.import_module(old) is importlib.import_module(MOVED[old])


def test_a_pickle_naming_a_class_by_its_old_module_loads_the_class():
    from lac_rllib.families.on_policy.module import OnPolicyTorchRLModule

    old = b"clac_rllib.constrained.on_policy_module\nOnPolicyTorchRLModule\n."  # protocol 0: a global
    assert pickle.loads(old) is OnPolicyTorchRLModule


def test_a_name_that_never_existed_still_fails():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("lac_rllib.constrained.no_such_module")
