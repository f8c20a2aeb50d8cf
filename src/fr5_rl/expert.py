"""A scripted expert for both tasks: inverse-kinematics waypoints turned into actions.

It reads the simulator's ground truth (object pose, joint state) and emits the same 7-D
actions a policy would, so it exercises the full action path. Used as a baseline, by the
tests (a task that the expert cannot solve is a broken task), and for demonstrations.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .envs import FR5Env
from .kinematics import InverseKinematics


class ScriptedExpert:
    """Waypoint expert: above the object -> down to it -> (grasp) close -> lift and hold.

    It keeps no memory between calls: the phase is read off the current state each step
    (where the tcp is relative to the object, whether both finger pads touch it), so it can
    label any state a learner visits (DAgger) and recovers when something goes wrong.
    """

    hover_height = 0.10  # m above the object centre before descending
    lift_clearance = 0.10  # m the expert lifts (the task needs lift_height)
    grasp_height_offset = 0.015  # m above the object centre where the fingers close
    align_tolerance = 0.01  # m horizontal error under which the expert descends
    at_grasp_tolerance = 0.008  # m from the grasp point under which it closes
    # Cartesian speed per phase (m per 20 ms control step): fast in free space, slow near the
    # object so that the arm's few steps of tracking lag do not overshoot into it.
    phase_speed = {"hover": 0.015, "descend": 0.006, "close": 0.006, "lift": 0.006}

    def __init__(self, env) -> None:
        self.env: FR5Env = env.unwrapped
        spec = self.env.robot_spec
        _, home_rotation = self.env.kinematics.tcp_pose(spec.home_joint_positions)
        # Keep the home pose's tcp yaw: only the approach axis matters to the tasks.
        self._down_rotation = home_rotation.ravel().tolist()
        # The arm's own kinematics, not PyBullet's solver: converged (PyBullet's left 1-4 mm of
        # each step undone) and 4-5x cheaper, which matters where the expert replays thousands of
        # starts (the reverse curriculum).
        self._inverse = InverseKinematics(self.env.kinematics)
        self._max_step = self.env.cfg.action.max_joint_step
        self.phase = "hover"

    def reset(self) -> None:
        """Nothing to forget (the expert is stateless); kept for a uniform actor interface."""
        self.phase = "hover"

    def act(self, observation: Optional[np.ndarray] = None) -> np.ndarray:
        """Next action in [-1, 1]^7 (the observation is unused: the expert reads the simulator)."""
        env = self.env
        state = env.task_state()
        q, tcp, obj = (np.asarray(v) for v in (state.joint_positions, state.tcp_position, state.object_position))
        grasp = env.task.name == "grasp"
        grasp_point = obj + np.array([0.0, 0.0, self.grasp_height_offset if grasp else 0.0])
        horizontal_error = float(np.linalg.norm((grasp_point - tcp)[:2]))
        held = grasp and state.fingers_object_contact == 2 and \
            env.gripper_command_width < env.robot_spec.max_opening_width / 2.0
        if held:
            self.phase, target = "lift", obj + np.array([0.0, 0.0, self.lift_clearance])
            target[2] = state.object_start_position[2] + self.grasp_height_offset + self.lift_clearance
        elif grasp and np.linalg.norm(grasp_point - tcp) < self.at_grasp_tolerance:
            self.phase, target = "close", grasp_point
        elif horizontal_error < self.align_tolerance + 0.5 * max(tcp[2] - grasp_point[2], 0.0):
            # A funnel: the higher above the grasp point, the more lateral error is fine, since
            # the straight line down removes it on the way.
            self.phase, target = "descend", grasp_point
        else:
            self.phase, target = "hover", obj + np.array([0.0, 0.0, self.hover_height])
        # Straight-line Cartesian motion: IK for a point a short step along the line, slowing
        # down over the last centimetres.
        offset = target - tcp
        distance = float(np.linalg.norm(offset))
        speed = self.phase_speed[self.phase]
        if self.phase == "descend" and tcp[2] - grasp_point[2] > 0.06:
            speed = self.phase_speed["hover"]  # slow only for the last centimetres
        step = min(speed, 0.35 * distance)
        if distance > step:
            target = tcp + offset * (step / distance)
        q_target = self._inverse_kinematics(target, q)
        delta = (q_target - q) / self._max_step
        # Scale the whole joint step (not per joint) so the motion keeps its direction.
        action = np.zeros(7)
        action[:6] = delta / max(1.0, float(np.max(np.abs(delta))))
        action[6] = -1.0 if self.phase in ("close", "lift") else 1.0
        return action.astype(np.float32)

    def _inverse_kinematics(self, tcp_target: np.ndarray, start: np.ndarray) -> np.ndarray:
        """Joint angles (rad) that put the tcp at ``tcp_target`` (m, base_link), pointing down,
        found from ``start`` (the measured joints, rad); the last iterate if not converged (the
        action then scales it to one step all the same)."""
        joints, _ = self._inverse.solve(start, tcp_target, self._down_rotation)
        return np.asarray(joints)
