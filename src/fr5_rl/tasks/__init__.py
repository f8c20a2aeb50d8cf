"""Tasks: what the arm must do, how it is judged and rewarded. One task per module: every module
here is imported, and each :class:`Task` subclass registers itself in :data:`TASKS` by name."""
import importlib
import pkgutil

from .base import (TASKS, EpisodeVerdict, Task, TaskOutcome, TaskState, fingers_around_as_the_camera_sees,
                   held_as_the_camera_sees, task_state_from)

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")

from .grasp import GraspTask  # noqa: E402  (imported above; named for callers)
from .place import PlaceTask  # noqa: E402
from .reach import ReachTask  # noqa: E402

__all__ = ["TASKS", "EpisodeVerdict", "Task", "TaskOutcome", "TaskState", "fingers_around_as_the_camera_sees",
           "held_as_the_camera_sees",
           "task_state_from", "ReachTask", "GraspTask", "PlaceTask"]
