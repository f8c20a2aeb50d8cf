"""Pick the object up and set it down at a goal pose on the table: the production line's job."""
from __future__ import annotations

import math
from typing import Dict, Optional, Sequence, Tuple

from ..draws import EpisodeDraws
from ..env_config import EnvConfig
from ..objects import ObjectShape, yaw_of
from .base import ObjectTask, TaskOutcome, TaskState


class PlaceTask(ObjectTask):
    """Set the object down at a goal (x, y and, for a box, yaw) and let go of it.

    Success (all at once, within ``place.max_steps``): the object within
    ``place.position_tolerance`` of the goal (xy); a box's yaw within ``place.yaw_tolerance_deg``
    of the goal's, modulo its top's symmetry (a cylinder has no yaw to match); upright within
    ``place.upright_tolerance_deg``; released (no finger touches it, and the tcp is at least
    ``place.release_clearance`` above its top); at rest (slower than ``place.rest_speed``).

    The shaping potential leads through the job: the tcp to the object (``approach``), the gripper
    closed near it and open once the object is at the goal (``gripper``), the object lifted to
    ``place.carry_height`` while it is away from the goal and down at it (``lift``), the object to
    the goal (``carry``) and a box to the goal's yaw (``yaw``), the tcp clear above the placed
    object (``release``).
    """

    name = "place"
    include_lift = True
    include_goal = True

    def __init__(self, cfg: EnvConfig, max_opening_width: float) -> None:
        place = cfg.place
        super().__init__(cfg, max_opening_width, place.knocked_over_angle_deg, place.out_of_reach_margin)
        self.settings = place
        self.upright_cos = math.cos(math.radians(place.upright_tolerance_deg))
        self.yaw_tolerance = math.radians(place.yaw_tolerance_deg)
        self.goal: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.shape: Optional[ObjectShape] = None
        self._previous_object: Optional[Sequence[float]] = None
        self.object_speed = 0.0  # m/s, over the last period

    def reset(self) -> None:
        super().reset()
        self._previous_object = None
        self.object_speed = 0.0

    def start(self, draws: EpisodeDraws, shape: ObjectShape) -> None:
        if draws.goal is None:
            raise ValueError("the place task needs a goal: draw the episode for the task 'place'")
        self.goal, self.shape = draws.goal, shape

    # ------------------------------------------------------------------ measures
    def goal_distance(self, state: TaskState) -> float:
        """m from the object's centre to the goal, in the table's plane."""
        return math.hypot(state.object_position[0] - self.goal[0], state.object_position[1] - self.goal[1])

    def yaw_error(self, state: TaskState) -> float:
        """rad from the object's yaw to the goal's, modulo its top's symmetry (0 for a cylinder)."""
        return self.shape.yaw_error(yaw_of(state.object_quaternion), self.goal[2])

    def lift(self, state: TaskState) -> float:
        """m of the object's centre above where it stood."""
        return state.object_position[2] - state.object_start_position[2]

    def clearance(self, state: TaskState) -> float:
        """m from the object's top up to the tcp."""
        return state.tcp_position[2] - (state.object_position[2] + self.shape.size[2] / 2.0)

    def released(self, state: TaskState) -> bool:
        return (state.fingers_object_contact == 0 and not state.arm_object_contact
                and self.clearance(state) >= self.settings.release_clearance)

    # ------------------------------------------------------------------ the task
    def terms(self, state: TaskState) -> Dict[str, float]:
        place = self.settings
        goal_distance = self.goal_distance(state)
        at_goal = goal_distance <= place.position_tolerance
        near = state.tcp_to_object_distance < place.close_distance
        wanted_width = self.max_opening_width if at_goal or not near else 0.0
        held = state.fingers_object_contact == 2
        wanted_lift = 0.0 if goal_distance <= 2.0 * place.position_tolerance else place.carry_height
        lift = -abs(self.lift(state) - wanted_lift) / place.carry_height if held else -wanted_lift / place.carry_height
        release = min(max(self.clearance(state), 0.0) / place.release_clearance, 1.0) if at_goal and not held else 0.0
        order = self.shape.symmetry_order
        yaw = -self.yaw_error(state) / (math.pi / order) if order else 0.0
        return {
            "approach": 0.0 if at_goal else self.approach_term(state),
            "orientation": self.orientation_term(state),
            "gripper": self.gripper_term(state, wanted_width),
            "lift": lift,
            "carry": -goal_distance / self.distance_scale,
            "yaw": yaw,
            "release": release,
        }

    def judge(self, state: TaskState, control_dt: float) -> TaskOutcome:
        position = state.object_position
        if self._previous_object is not None:
            self.object_speed = math.dist(position, self._previous_object) / control_dt
        self._previous_object = position
        terms = self.terms(state)
        failure = self.handling_failure(state)
        if failure is not None:
            return TaskOutcome(False, failure, terms)
        place = self.settings
        success = (self.goal_distance(state) <= place.position_tolerance
                   and self.yaw_error(state) <= self.yaw_tolerance
                   and float(state.object_up_axis[2]) >= self.upright_cos
                   and self.released(state)
                   and self.object_speed <= place.rest_speed)
        return TaskOutcome(success, None, terms)
