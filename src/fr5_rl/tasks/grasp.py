"""FR5Grasp: reach, close the fingers on the object, lift it and hold it up."""
from __future__ import annotations

import math
from typing import Dict


from ..env_config import EnvConfig
from .base import ObjectTask, TaskOutcome, TaskState


class GraspTask(ObjectTask):
    """Success: the object's centre stays at least ``lift_height`` above its start for
    ``hold_time`` seconds. Failure: any robot contact with the table, the arm or palm hitting
    the object, the object knocked over (tilt past ``knocked_over_angle_deg``) or pushed off
    the table region, the tcp leaving the workspace; the step limit truncates.
    """

    name = "grasp"
    include_lift = True

    def __init__(self, cfg: EnvConfig, max_opening_width: float) -> None:
        grasp = cfg.grasp
        super().__init__(cfg, max_opening_width, grasp.knocked_over_angle_deg, grasp.out_of_reach_margin)
        self.lift_height = grasp.lift_height
        self.hold_time = grasp.hold_time
        # Close when the tcp is this close to the grasp point (m): the shaping's cue.
        self.close_distance = grasp.close_distance
        self.grasp_point_height = grasp.grasp_point_height
        self.lifted_time = 0.0

    def reset(self) -> None:
        super().reset()
        self.lifted_time = 0.0

    def lift(self, state: TaskState) -> float:
        """Height (m) of the object centre above where it was placed."""
        return state.object_position[2] - state.object_start_position[2]

    def grasp_point_distance(self, state: TaskState) -> float:
        """Distance (m) from the tcp to the grasp point, ``grasp_point_height`` above the object
        centre (the centre itself at 0)."""
        if not self.grasp_point_height:
            return state.tcp_to_object_distance
        (tcp_x, tcp_y, tcp_z), (object_x, object_y, object_z) = state.tcp_position, state.object_position
        return math.dist((tcp_x, tcp_y, tcp_z), (object_x, object_y, object_z + self.grasp_point_height))

    def terms(self, state: TaskState) -> Dict[str, float]:
        distance = self.grasp_point_distance(state)
        near = distance < self.close_distance
        wanted_width = 0.0 if near else self.max_opening_width
        held = state.fingers_object_contact == 2
        return {
            "approach": -distance / self.distance_scale,
            "orientation": self.orientation_term(state),
            "gripper": self.gripper_term(state, wanted_width),
            "lift": min(max(self.lift(state), 0.0) / self.lift_height, 1.0) if held else 0.0,
        }

    def judge(self, state: TaskState, control_dt: float) -> TaskOutcome:
        terms = self.terms(state)
        failure = self.handling_failure(state)
        if failure is not None:
            return TaskOutcome(False, failure, terms)
        if self.lift(state) >= self.lift_height:
            self.lifted_time += control_dt
        else:
            self.lifted_time = 0.0
        success = self.lifted_time >= self.hold_time - 1e-9
        return TaskOutcome(success, None, terms)
