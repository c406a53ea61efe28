"""The batched navigation env against the stock one, step by step (the check behind the claim
"bit-identical to Safety-Gymnasium").

Both sides get the same seeds and the same action stream: N stock envs (safety_gymnasium 1.0.0 as
this project runs it: the compat shim and light resets, lac_rllib/tasks/safety_gym.py) in
gymnasium's ``SyncVectorEnv``, and one :class:`~lac_rllib.tasks.batched_navigation.BatchedNavigationEnv`.
After every step it compares every observation, reward, terminated, truncated and info key
(``cost_*``, ``cost_sum``, ``cost``, ``goal_met``) exactly, values and dtypes, and the layout of
every env (the one its last reset sampled, with each resampled goal). A Point's actions steer
towards the goal most of the time (so goals are reached and resampled, hazards entered), other
robots' are uniform noise; they are computed from the stock side's observations, so both sides
see the same actions whatever happens.

``python -m lac_rllib.tasks.navigation_equality SafetyPointGoal1-v0 --steps 2000`` runs it;
benchmarks/batched_equality.py runs it over every batched id at length, and
tests/tasks/test_batched_navigation.py over a short stream per id.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np


@dataclasses.dataclass
class Comparison:
    """What one stream compared, and where the two sides differed (none: identical)."""

    env_id: str
    num_envs: int
    steps: int = 0  #: env steps compared (vector steps × envs)
    episodes: int = 0  #: episode ends (each followed by a reset whose layout is compared)
    goals: int = 0  #: goals reached (each resampled)
    cost_steps: int = 0  #: env steps with cost 1
    mismatches: list = dataclasses.field(default_factory=list)  #: (vector step, what differed)

    @property
    def identical(self) -> bool:
        return not self.mismatches

    def line(self) -> str:
        verdict = "identical" if self.identical else f"{len(self.mismatches)} mismatches, first {self.mismatches[0]}"
        return (f"{self.env_id}: {self.steps:,} env steps over {self.num_envs} envs, {self.episodes} resets, "
                f"{self.goals} goals, {self.cost_steps} steps with cost: {verdict}")


def _goal_lidar(env) -> int:
    """Where the goal's lidar starts in the flat observation."""
    at = 0
    for key, space in env.unwrapped.task.obs_info.obs_space_dict.items():
        if key == "goal_lidar":
            return at
        at += int(np.prod(space.shape))
    raise ValueError("no goal lidar in the observation")


def _actions(obs, start: int, shape, rng, seek: bool, point: bool) -> np.ndarray:
    """Towards the goal lidar's strongest bin (a Point drives and turns; other robots get noise)."""
    noise = rng.uniform(-1, 1, size=shape)
    if not seek or not point:
        return noise.astype(np.float32)
    b = obs[:, start:start + 16].argmax(1)
    ang = (b + 0.5) * 2 * np.pi / 16
    ang = np.where(ang > np.pi, ang - 2 * np.pi, ang)
    a = np.stack([(np.cos(ang) > 0.7).astype(float), np.clip(2 * ang, -1, 1)], axis=1)
    return np.clip(a + 0.3 * noise, -1, 1).astype(np.float32)


def _layouts(envs) -> list:
    return [{k: np.asarray(v).tolist() for k, v in e.unwrapped.task.world_info.layout.items()} for e in envs]


def compare(env_id: str, num_envs: int = 4, vector_steps: int = 500, seed: int = 0,
            max_episode_steps: int | None = None, batched=None, env_config: dict | None = None) -> Comparison:
    """``vector_steps`` steps of ``num_envs`` stock envs and of the batched env (or ``batched``, a
    vector env built alike, e.g. one with a deliberate error), seeded ``seed``, compared; both
    built with ``env_config`` (e.g. ``{"robot_variant": "safety_gym"}``)."""
    from gymnasium.vector import SyncVectorEnv

    from lac_rllib.tasks.safety_gym import make_batched, make_env

    extra = dict(env_config or {})
    cfg = {**extra, "env_id": env_id} | ({"max_episode_steps": max_episode_steps} if max_episode_steps else {})
    stock = SyncVectorEnv([lambda: make_env(cfg) for _ in range(num_envs)])
    fast = batched or make_batched(env_id, num_envs, max_episode_steps, **extra)
    out = Comparison(env_id, num_envs)
    o1, _ = stock.reset(seed=seed)
    o2, _ = fast.reset(seed=seed)
    if not np.array_equal(o1, o2):
        out.mismatches.append((0, "reset observation"))
    if _layouts(stock.envs) != _layouts(fast.envs):
        out.mismatches.append((0, "layout"))
    rng = np.random.default_rng(seed)
    start, shape = _goal_lidar(stock.envs[0]), (num_envs, *stock.single_action_space.shape)
    point = "Point" in env_id
    for t in range(1, vector_steps + 1):
        a = _actions(o1, start, shape, rng, seek=t % 200 < 150, point=point)
        r1, r2 = stock.step(a), fast.step(a)
        o1 = r1[0]
        for name, x, y in zip(("observation", "reward", "terminated", "truncated"), r1[:4], r2[:4]):
            if x.dtype != y.dtype or not np.array_equal(x, y):
                out.mismatches.append((t, name))
        i1, i2 = r1[4], r2[4]
        if set(i1) != set(i2) or any(not np.array_equal(i1[k], i2[k]) or i1[k].dtype != i2[k].dtype for k in i1):
            out.mismatches.append((t, "info"))
        if _layouts(stock.envs) != _layouts(fast.envs):  # after a reset or a goal's resampling
            out.mismatches.append((t, "layout"))
        out.steps += int(i1.get("_cost", np.zeros(num_envs, bool)).sum())  # the envs that stepped (not reset)
        out.episodes += int((r1[2] | r1[3]).sum())
        out.goals += int(i1.get("goal_met", np.zeros(num_envs, bool)).sum())
        out.cost_steps += int(np.asarray(i1.get("cost", 0.0)).astype(bool).sum())
    stock.close()
    fast.close()
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m lac_rllib.tasks.navigation_equality", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("env_id", nargs="+")
    p.add_argument("--envs", type=int, default=4)
    p.add_argument("--steps", type=int, default=500, help="vector steps")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episode-steps", type=int, default=None, help="shorter episodes: more resets")
    args = p.parse_args(argv)
    failed = 0
    for env_id in args.env_id:
        c = compare(env_id, args.envs, args.steps, args.seed, args.episode_steps)
        print(c.line(), flush=True)
        failed += not c.identical
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
