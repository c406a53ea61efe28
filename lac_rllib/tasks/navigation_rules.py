"""What each navigation task family scores, batched over N envs: its reward, when its goal is met,
and the ``cost_*`` indicators of its constrained objects (safety_gymnasium 1.0.0's
``tasks/safe_navigation/{goal,button,push}/*_level0.py`` and ``assets/*``, line for line; the
arithmetic is lac_rllib/tasks/navigation_layer.py's).

A rule reads a :class:`Frame`: the positions of the bodies the task reads (the agent first) and,
where a cost or goal is decided by contact, each env's contacts as the pairs of geom ids MuJoCo
reports. It keeps the per-env state the stock task keeps between steps (the last distances) as
arrays, and reads it back from safety_gymnasium's task object where the stock code set it (at
reset, and when a goal is met and resampled).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from lac_rllib.tasks import navigation_layer as layer

#: Obstacles whose cost is a contact of an agent geom with one of theirs: name → geom-name prefix.
CONTACT_COSTS = {"vases": "vase", "gremlins": "gremlin", "pillars": "pillar", "buttons": "button"}


@dataclasses.dataclass
class Frame:
    """One step's readings of the live envs."""

    xpos: np.ndarray  #: (N, B, 3) body positions: the agent, then each group (``groups``)
    groups: dict  #: group name → slice of ``xpos``'s bodies
    touching: list  #: per env: geom-name prefix (or "goal_button") → an agent geom touches one
    tasks: list  #: per env: safety_gymnasium's task object
    _dist: np.ndarray | None = None

    def at(self, name: str) -> np.ndarray:
        return self.xpos[:, self.groups[name]]

    def dist_xy(self, name: str) -> np.ndarray:
        """(N, K) XY distances from the agent to group ``name``'s objects (all groups' computed once)."""
        if self._dist is None:
            self._dist = layer.dist_xy(self.xpos[:, 1:], self.agent)
        g = self.groups[name]
        return self._dist[:, g.start - 1:g.stop - 1]

    @property
    def agent(self) -> np.ndarray:
        return self.xpos[:, 0]


class GoalRule:
    """GoalLevel0: progress towards the goal (XY) plus ``reward_goal`` within ``goal.size``."""

    def __init__(self, task, num_envs: int) -> None:
        self.task = task
        self.last_dist = np.zeros(num_envs)

    def reset(self, i: int, task) -> None:
        self.last_dist[i] = task.last_dist_goal

    def reward(self, f: Frame, live: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dist = f.dist_xy("goal")[:, 0]
        reward = 0.0 + (self.last_dist[live] - dist) * self.task.goal.reward_distance
        self.last_dist[live] = dist
        achieved = dist <= self.task.goal.size
        return np.where(achieved, reward + self.task.goal.reward_goal, reward), achieved

    def step(self, f: Frame) -> None:
        """``specific_step``: nothing for Goal."""


class ButtonRule(GoalRule):
    """ButtonLevel0: progress towards the goal button (XY), ``reward_goal`` for touching it; the
    buttons' timer: after a goal, for ``resampling_delay`` steps no button costs and the buttons'
    lidar reads 0."""

    def reward(self, f: Frame, live: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dist = f.dist_xy("goal")[:, 0]
        reward = 0.0 + (self.last_dist[live] - dist) * self.task.buttons.reward_distance
        self.last_dist[live] = dist
        achieved = np.array([t["goal_button"] for t in f.touching])
        return np.where(achieved, reward + self.task.buttons.reward_goal, reward), achieved

    def step(self, f: Frame) -> None:
        for task in f.tasks:  # Buttons.timer_tick, on the stock object that keeps the timer
            task.specific_step()


class PushRule(GoalRule):
    """PushLevel0: the agent's progress towards the box (gated off within ``null_dist`` box sizes),
    the box's progress towards the goal (3-D distances), ``reward_goal`` with the box in the goal."""

    def __init__(self, task, num_envs: int) -> None:
        super().__init__(task, num_envs)
        self.last_box, self.last_box_goal = np.zeros(num_envs), np.zeros(num_envs)

    def reset(self, i: int, task) -> None:
        super().reset(i, task)
        self.last_box[i], self.last_box_goal[i] = task.last_dist_box, task.last_box_goal

    def reward(self, f: Frame, live: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        box, goal, t = f.at("push_box")[:, 0], f.at("goal")[:, 0], self.task
        dist_box = np.sqrt(np.sum(np.square(box - f.agent), axis=-1))
        gate = self.last_box[live] > t.push_box.null_dist * t.push_box.size
        reward = 0.0 + (self.last_box[live] - dist_box) * t.push_box.reward_box_dist * gate
        self.last_box[live] = dist_box
        dist_box_goal = np.sqrt(np.sum(np.square(box - goal), axis=-1))
        reward = reward + (self.last_box_goal[live] - dist_box_goal) * t.push_box.reward_box_goal
        self.last_box_goal[live] = dist_box_goal
        achieved = dist_box_goal <= t.goal.size
        return np.where(achieved, reward + t.goal.reward_goal, reward), achieved


RULES = {"Goal": GoalRule, "Button": ButtonRule, "Push": PushRule}


def constrained(task) -> list:
    """The task's constrained obstacles, in ``calculate_cost``'s order (read once: the task's
    ``_obstacles`` builds its list at every access)."""
    return [ob for ob in task._obstacles if getattr(ob, "is_constrained", False)]


def needs_contacts(task) -> bool:
    """Whether the task scores anything by contact (a constrained contact cost, the Button goal)."""
    contact_cost = any(ob.name in CONTACT_COSTS for ob in constrained(task))
    return contact_cost or getattr(task, "buttons", None) is not None


def costs(obstacles: list, f: Frame) -> dict[str, np.ndarray]:
    """``BaseTask.calculate_cost`` under ``constrain_indicator`` for the task's constrained
    ``obstacles`` (:func:`constrained`): each one's ``cost_*`` (1.0 where it costs) in their order,
    and ``cost_sum``. The buttons' key is there only for the envs whose timer is 0 (NaN elsewhere:
    the env has no such key)."""
    out = {}
    for ob in obstacles:
        if ob.name == "hazards":
            out["cost_hazards"] = layer.hazard_violation(f.dist_xy("hazards"), ob.size).astype(float)
        elif ob.name == "vases":
            out["cost_vases_contact"] = np.array([float(t["vase"]) for t in f.touching])
            if ob.velocity_cost:
                out["cost_vases_velocity"] = np.array([float(t["vase_moving"]) for t in f.touching])
        elif ob.name == "buttons":
            active = np.array([tk.buttons.timer == 0 for tk in f.tasks])
            out["cost_buttons"] = np.where(active, [float(t["wrong_button"]) for t in f.touching], np.nan)
        else:
            out[f"cost_{ob.name}"] = np.array([float(t[CONTACT_COSTS[ob.name]]) for t in f.touching])
    values = list(out.values())  # NaN (no such key in that env) > 0 is False
    out["cost_sum"] = (np.any(np.stack(values) > 0, axis=0) if values else np.zeros(len(f.tasks), bool)).astype(float)
    return out


def check(task) -> None:
    """A NotImplementedError for what the rules above do not cover (the task is run stock)."""
    for ob in task._obstacles:
        if getattr(ob, "is_constrained", False) and ob.name not in ("hazards", *CONTACT_COSTS):
            raise NotImplementedError(f"the batched backend has no cost for {ob.name}")
        if ob.name == "vases" and ob.is_constrained and ob.displace_cost:
            raise NotImplementedError("vases.displace_cost > 0 is not batched")
        if getattr(ob, "is_comp_observed", False):
            raise NotImplementedError(f"{ob.name}'s compass is not batched")
    if task._is_load_static_geoms and task.static_geoms_contact_cost:
        raise NotImplementedError("static geoms' contact cost is not batched")
    if task.lidar_conf.type != "pseudo":
        raise NotImplementedError(f"lidar type {task.lidar_conf.type!r} is not batched")
    if task.action_noise:
        raise NotImplementedError("action noise is not batched")
