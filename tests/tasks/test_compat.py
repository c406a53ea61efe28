"""safety_gym_compat: apply() is idempotent, fixes what docs/dependencies.md lists and changes nothing else."""

import dataclasses
import json
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

from lac_rllib.tasks import registry, safety_gym_compat

# Seeded Ant-v5 rollout; prints a fingerprint of every float it produced.
_ANT_TRAJECTORY = textwrap.dedent(
    """
    import hashlib, json, sys
    import gymnasium as gym, numpy as np
    if sys.argv[1] == "with":
        from lac_rllib.tasks import safety_gym_compat
        safety_gym_compat.apply()
        import safety_gymnasium  # noqa: F401
    env = gym.make("Ant-v5")
    env.action_space.seed(3)
    h = hashlib.sha256()
    obs, _ = env.reset(seed=7)
    h.update(obs.tobytes())
    for _ in range(300):
        obs, rew, term, trunc, info = env.step(env.action_space.sample())
        for part in (obs.tobytes(), np.float64(rew).tobytes(), bytes([term, trunc])):
            h.update(part)
        if term or trunc:
            obs, _ = env.reset()
            h.update(obs.tobytes())
    print(json.dumps({"digest": h.hexdigest(), "safety": "safety_gymnasium" in sys.modules}))
    """
)


def _run(code: str, *args: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _patched_objects() -> list:
    registration = sys.modules["safety_gymnasium.utils.registration"]
    base_agent = sys.modules["safety_gymnasium.bases.base_agent"]
    return [
        registration.EnvSpec,
        registration._find_spec,
        base_agent.BaseAgent._init_jnt_sensors,
        dataclasses._get_field,
        *(gym.registry[t] for t in ("SafetyPointGoal1-v0", "SafetyAntVelocity-v1")),
    ]


def test_apply_is_idempotent():
    first = safety_gym_compat.apply()
    objects = _patched_objects()
    second = safety_gym_compat.apply()
    assert second is first and safety_gym_compat.is_applied()
    assert all(a is b for a, b in zip(objects, _patched_objects(), strict=True))
    # Not wrapped twice: the Car fix wraps the original method exactly once.
    method = sys.modules["safety_gymnasium.bases.base_agent"].BaseAgent._init_jnt_sensors
    assert not getattr(method.__wrapped__, "_lac_rllib_patched", False)


def test_temporary_shims_are_gone_after_apply():
    safety_gym_compat.apply()
    for name in ("gymnasium.wrappers.compatibility", "gymnasium.wrappers.autoreset",
                 "gymnasium.wrappers.time_limit", "gymnasium.wrappers.env_checker",
                 "gymnasium.wrappers.normalize"):
        assert name not in sys.modules
    # dataclasses is back to normal: ndarray defaults outside safety_gymnasium still rejected.
    assert dataclasses._get_field.__module__ == "dataclasses"
    with pytest.raises(ValueError, match="mutable default"):
        @dataclasses.dataclass
        class _Bad:
            color: np.ndarray = np.zeros(3)


def test_ndarray_defaults_keep_python310_semantics():
    safety_gym_compat.apply()
    from safety_gymnasium.assets.color import COLOR
    from safety_gymnasium.assets.geoms import Hazards

    field = {f.name: f for f in dataclasses.fields(Hazards)}["color"]
    assert field.default is COLOR["hazard"]  # the very same array, no factory
    assert Hazards.color is COLOR["hazard"]  # class attribute kept
    assert Hazards().color is COLOR["hazard"]


def test_gymnasium_envspec_untouched():
    safety_gym_compat.apply()
    spec_cls = gym.envs.registration.EnvSpec
    assert not hasattr(spec_cls, "apply_api_compatibility")
    with pytest.raises(TypeError):
        spec_cls(id="Nothing-v0", autoreset=True)
    # ... while safety_gymnasium's registration module sees the extended spec.
    spec = safety_gym_compat.safety_spec("SafetyPointGoal1-v0")
    assert isinstance(spec, safety_gym_compat.SafetyEnvSpec)
    assert spec.apply_api_compatibility is False and spec.autoreset is False
    assert spec.entry_point == "safety_gymnasium.builder:Builder"


def test_registry_ids_are_ours_and_safety_make_still_works():
    sg = safety_gym_compat.apply()
    for task_id in ("SafetyPointGoal1-v0", "SafetyCarButton1-v0", "SafetyHumanoidVelocity-v1"):
        assert gym.registry[task_id].entry_point is registry._gym_entry_point
    # safety_gymnasium's own make still builds its 6-tuple env for the same id ...
    raw = sg.make("SafetyPointGoal1-v0")
    raw.reset(seed=0)
    assert len(raw.step(raw.action_space.sample())) == 6
    # ... and its gymnasium-form id still works (5-tuple with info["cost"]).
    env = gym.make("SafetyPointGoal1Gymnasium-v0")
    env.reset(seed=0)
    out = env.step(env.action_space.sample())
    assert len(out) == 5 and "cost" in out[4]


def test_multi_agent_stub_raises_cleanly():
    safety_gym_compat.apply()
    import importlib.util

    if importlib.util.find_spec("gymnasium_robotics") is not None:
        pytest.skip("gymnasium_robotics is installed: no stub")
    from safety_gymnasium.tasks.safe_multi_agent import safe_mujoco_multi

    with pytest.raises(ImportError, match="gymnasium_robotics"):
        safe_mujoco_multi.MultiAgentMujocoEnv()
    assert "gymnasium_robotics" not in sys.modules


def test_gymnasium_mujoco_env_bit_identical_with_and_without_patch():
    without = _run(_ANT_TRAJECTORY, "without")  # fresh process, never patched
    with_ = _run(_ANT_TRAJECTORY, "with")
    assert not without["safety"] and with_["safety"]
    assert with_["digest"] == without["digest"]
    # And in this (patched) process too.
    safety_gym_compat.apply()
    in_process = _run_inline()
    assert in_process == without["digest"]


def _run_inline() -> str:
    import hashlib

    env = gym.make("Ant-v5")
    env.action_space.seed(3)
    h = hashlib.sha256()
    obs, _ = env.reset(seed=7)
    h.update(obs.tobytes())
    for _ in range(300):
        obs, rew, term, trunc, _ = env.step(env.action_space.sample())
        for part in (obs.tobytes(), np.float64(rew).tobytes(), bytes([term, trunc])):
            h.update(part)
        if term or trunc:
            obs, _ = env.reset()
            h.update(obs.tobytes())
    return h.hexdigest()


def test_importing_tasks_is_cheap_and_plain_safety_import_needs_the_patch():
    code = textwrap.dedent(
        """
        import json, sys
        import lac_rllib.tasks
        cheap = not any(m in sys.modules for m in ("mujoco", "safety_gymnasium"))
        try:
            import safety_gymnasium  # unpatched: must fail on this stack
            plain = "ok"
        except Exception as e:
            plain = type(e).__name__
        print(json.dumps({"cheap": cheap, "plain": plain}))
        """
    )
    out = _run(code)
    assert out["cheap"]
    assert out["plain"] != "ok"  # if this starts passing, the stack changed: revisit the patches


def test_apply_reclaims_ids_taken_over_later():
    """If safety_gymnasium's spec lands in gymnasium's registry again, apply() puts ours back."""
    safety_gym_compat.apply()
    theirs = safety_gym_compat._SAFETY_SPECS["SafetyCarGoal1-v0"]
    ours = gym.registry["SafetyCarGoal1-v0"]
    try:
        gym.registry["SafetyCarGoal1-v0"] = theirs
        safety_gym_compat.apply()
        assert gym.registry["SafetyCarGoal1-v0"].entry_point is registry._gym_entry_point
    finally:
        gym.registry["SafetyCarGoal1-v0"] = ours
    with pytest.raises(ValueError):
        safety_gym_compat.safety_spec("focops/AntVelocity-v0")
