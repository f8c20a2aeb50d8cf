"""A scripted expert for both tasks: inverse-kinematics waypoints turned into actions.

It reads the simulator's ground truth (object pose, joint state) and emits the same 7-D
actions a policy would, so it exercises the full action path. Used as a baseline, by the
tests (a task that the expert cannot solve is a broken task), and for demonstrations.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import pybullet as p

from .envs import FR5Env
from .transforms import quaternion_from_matrix


class ScriptedExpert:
    """Waypoint expert: above the object -> down to it -> (grasp) close -> lift and hold."""

    hover_height = 0.10  # m above the object centre before descending
    lift_clearance = 0.10  # m the expert lifts (the task needs lift_height)
    waypoint_tolerance = 0.01  # m
    grasp_height_offset = 0.015  # m above the object centre where the fingers close
    close_steps = 30  # control steps the fingers get to close (0.6 s: full stroke ~0.5 s)
    # Cartesian speed per phase (m per 20 ms control step): fast in free space, slow near the
    # object so that the arm's few steps of tracking lag do not overshoot into it.
    phase_speed = {"hover": 0.015, "descend": 0.006, "close": 0.006, "lift": 0.006}

    def __init__(self, env) -> None:
        self.env: FR5Env = env.unwrapped
        spec = self.env.robot_spec
        home_position, home_rotation = self.env.kinematics.tcp_pose(spec.home_joint_positions)
        # Keep the home pose's tcp yaw: only the approach axis matters to the tasks.
        self._down_quaternion = list(quaternion_from_matrix(home_rotation))
        self._lower = spec.lower_limits.tolist() + [0.0, 0.0]
        self._upper = spec.upper_limits.tolist() + [spec.finger_travel] * 2
        self._ranges = [u - l for u, l in zip(self._upper, self._lower)]
        self._rest = spec.home_joint_positions.tolist() + [0.0, 0.0]
        self._max_step = float(self.env.cfg["action"]["max_joint_step"])
        self.reset()

    def reset(self) -> None:
        """Call after env.reset()."""
        self.phase = "hover"
        self._phase_steps = 0
        self._hold_point: Optional[np.ndarray] = None

    def _set_phase(self, phase: str) -> None:
        self.phase, self._phase_steps = phase, 0

    def act(self, observation: Optional[np.ndarray] = None) -> np.ndarray:
        """Next action in [-1, 1]^7 (the observation is unused: the expert reads the simulator)."""
        env = self.env
        q, _, _ = env.robot.joint_state()
        tcp, _ = env.kinematics.tcp_pose(q)
        obj = env.object_position()
        grasp = env.task.name == "grasp"
        self._phase_steps += 1
        if self.phase == "hover":
            target = obj + np.array([0.0, 0.0, self.hover_height])
            if np.linalg.norm(target - tcp) < self.waypoint_tolerance:
                self._set_phase("descend")
        if self.phase == "descend":
            target = obj + np.array([0.0, 0.0, self.grasp_height_offset if grasp else 0.0])
            error = np.linalg.norm(target - tcp)
            # Close once there, or once nearly there and no longer getting closer (the arm's
            # position controller can settle a few millimetres off under gravity).
            if grasp and (error < 0.005 or (self._phase_steps > 40 and error < 0.012)):
                self._set_phase("close")
                self._hold_point = target.copy()
        if self.phase == "close":
            target = self._hold_point
            if self._phase_steps > self.close_steps:
                self._set_phase("lift")
        if self.phase == "lift":
            target = self._hold_point + np.array([0.0, 0.0, self.lift_clearance])
        # Straight-line Cartesian motion: IK for a point a short step along the line, slowing
        # down over the last centimetres.
        offset = target - tcp
        distance = float(np.linalg.norm(offset))
        step = min(self.phase_speed[self.phase], 0.35 * distance)
        if distance > step:
            target = tcp + offset * (step / distance)
        q_target = self._inverse_kinematics(target)
        delta = (q_target - q) / self._max_step
        # Scale the whole joint step (not per joint) so the motion keeps its direction.
        action = np.zeros(7)
        action[:6] = delta / max(1.0, float(np.max(np.abs(delta))))
        action[6] = -1.0 if self.phase in ("close", "lift") else 1.0
        return action.astype(np.float32)

    def _inverse_kinematics(self, tcp_target: np.ndarray) -> np.ndarray:
        env = self.env
        solution = p.calculateInverseKinematics(
            env.robot.body, env.robot.tcp_link, tcp_target.tolist(), self._down_quaternion,
            lowerLimits=self._lower, upperLimits=self._upper, jointRanges=self._ranges,
            restPoses=self._rest, maxNumIterations=60, residualThreshold=1e-5,
            physicsClientId=env.world.client,
        )
        return np.asarray(solution[:6])
