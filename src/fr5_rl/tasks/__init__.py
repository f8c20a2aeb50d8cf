"""Tasks: what the FR5 must do, how it is judged and rewarded. One task per module."""
from .base import Task, TaskState, TaskOutcome
from .reach import ReachTask
from .grasp import GraspTask

__all__ = ["Task", "TaskState", "TaskOutcome", "ReachTask", "GraspTask"]
