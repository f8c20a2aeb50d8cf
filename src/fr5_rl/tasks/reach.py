"""FR5Reach: bring the open gripper around the object, pointing down, touching nothing."""
from __future__ import annotations

from typing import Dict

import numpy as np

from ..env_config import EnvConfig
from .base import Task, TaskOutcome, TaskState


class ReachTask(Task):
    """Success: tcp within ``success_distance`` of the object centre, approach axis within
    ``max_approach_angle_deg`` of straight down, fingers open, and no robot link other than the
    finger pads touching anything. Failure: a collision of the arm or palm with the table or
    the object, the tcp leaving the workspace; the step limit truncates.
    """

    name = "reach"

    def __init__(self, cfg: EnvConfig, max_opening_width: float) -> None:
        super().__init__(cfg, max_opening_width)
        reach = cfg.reach
        self.success_distance = reach.success_distance
        self.min_down_cosine = float(np.cos(np.deg2rad(reach.max_approach_angle_deg)))
        self.min_open_width = reach.min_open_width

    def terms(self, state: TaskState) -> Dict[str, float]:
        return {
            "approach": self.approach_term(state),
            "orientation": self.orientation_term(state),
            "gripper": self.gripper_term(state, self.max_opening_width),
        }

    def judge(self, state: TaskState, control_dt: float) -> TaskOutcome:
        terms = self.terms(state)
        failure = self.common_failure(state)
        if failure is not None:
            return TaskOutcome(False, failure, terms)
        success = (
            state.tcp_to_object_distance <= self.success_distance
            and -state.tcp_approach_axis[2] >= self.min_down_cosine  # approach angle within limit
            and state.gripper_width >= self.min_open_width
        )
        return TaskOutcome(success, None, terms)
