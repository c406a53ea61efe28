"""Safe tasks. Importing this package registers every built-in task id."""

from lac_rllib.tasks import mujoco_tasks as _mujoco_tasks  # noqa: F401  (registers)
from lac_rllib.tasks import point_hazard as _point_hazard  # noqa: F401  (registers)
from lac_rllib.tasks import safety_gym as _safety_gym  # noqa: F401  (registers)
from lac_rllib.tasks.registry import TaskSpec, get_task, known_tasks, register

__all__ = ["TaskSpec", "get_task", "known_tasks", "register"]
