"""The calibration's poses and its moves between them, free of ROS.

The poses (:func:`calibration_poses`) are joint configurations around ``centre`` in
config/calibration.yaml, drawn uniformly within ``spread`` and kept only when they stay inside
the joint-limit margin and the safety zone the policy node uses, keep the cup above the table
and in the camera's view, and tilt the tcp no more than ``max_tilt``: no inverse kinematics is
needed and every pose is reachable by construction.

The moves (:class:`CalibrationMove`) are the policy node's own slow start move
(:meth:`~fr5_rl.motion_guard.MotionGuard.start_move`: slowest-joint synchronised, at most
0.3 rad/s, hands over at rest), with its joint-limit margin (:meth:`MotionGuard.limit`), and
every command passes the deployment's :class:`~fr5_rl.deploy.deployment.SafetyGate` (limits,
per-period velocity, the safety zone) before it may be sent.
"""
from __future__ import annotations

import dataclasses
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..config import RobotSpec
from ..env_config import EnvConfig
from ..kinematics import ForwardKinematics, InverseKinematics
from ..perception.camera_model import Intrinsics
from ..perception.hand_eye import CalibrationSettings
from ..deploy.deployment import SafetyGate, SafetyZone
from ..motion_guard import MotionGuard, MotionGuardSettings


def centre_configuration(settings: CalibrationSettings, robot: RobotSpec) -> np.ndarray:
    """The arm's configuration (rad, j1..j6) at the centre of the poses: the tcp at
    ``centre_tcp``, straight down, turned by ``centre_yaw``, by inverse kinematics from home.

    :raises RuntimeError: the arm cannot reach it.
    """
    c, s = math.cos(settings.centre_yaw), math.sin(settings.centre_yaw)
    down = (c, s, 0.0, s, -c, 0.0, 0.0, 0.0, -1.0)  # tcp x = (c, s, 0), z = straight down
    joints, converged = InverseKinematics(ForwardKinematics(robot)).solve(
        robot.home_joint_positions, settings.centre_tcp, down, max_iterations=100)
    if not converged:
        raise RuntimeError(f"the {robot.model} cannot put its tcp at centre_tcp {settings.centre_tcp} pointing down: "
                           "move it in config/calibration.yaml")
    return np.asarray(joints)


def calibration_poses(settings: CalibrationSettings, robot: RobotSpec, env_cfg: EnvConfig,
                      guard: MotionGuardSettings, base_from_optical: np.ndarray, intrinsics: Intrinsics,
                      count: int, object_in_tcp: Sequence[float] = (0.0, 0.0, 0.0)) -> List[np.ndarray]:
    """``count`` arm configurations (rad, j1..j6) showing the cup to the camera, ordered so that
    consecutive ones are close (a short tour, greedy from the first).

    :param base_from_optical: 4x4 configured pose of the optical frame in base_link (m): the cup
        must project ``image_margin`` px inside the image there.
    :param object_in_tcp: m, the cup centre's assumed offset in the tcp frame.
    :raises RuntimeError: fewer than ``count`` valid configurations in ``max_draw`` draws.
    """
    rng = np.random.default_rng(settings.seed)
    kinematics = ForwardKinematics(robot)
    zone = SafetyZone(robot, env_cfg)
    lower = robot.lower_limits + guard.joint_limit_margin
    upper = robot.upper_limits - guard.joint_limit_margin
    centre, spread = centre_configuration(settings, robot), np.asarray(settings.spread)
    optical_from_base = np.linalg.inv(base_from_optical)
    table = env_cfg.table.top_height
    half_height = settings.cup.height / 2.0
    offset = np.asarray(object_in_tcp, dtype=np.float64)
    found: List[np.ndarray] = []
    for _ in range(settings.max_draw):
        if len(found) >= count:
            break
        q = centre + rng.uniform(-1.0, 1.0, 6) * spread
        if np.any(q < lower) or np.any(q > upper) or zone.check(q) is not None:
            continue
        position, rotation = kinematics.tcp_pose(q)
        tilt = math.acos(float(np.clip(-rotation[2, 2], -1.0, 1.0)))  # approach axis from straight down
        cup = position + rotation @ offset
        if tilt > settings.max_tilt:
            continue
        # The tilted cup's lowest point: its half height along the axis plus its radius across.
        lowest = cup[2] - half_height * abs(rotation[2, 2]) - settings.cup.radius * math.sin(tilt) - table
        if lowest < settings.min_cup_clearance or cup[2] - table > settings.max_cup_height:
            continue
        in_camera = optical_from_base[:3, :3] @ cup + optical_from_base[:3, 3]
        if in_camera[2] <= 0.1:
            continue
        u, v = intrinsics.project(in_camera)
        margin = settings.image_margin
        if not (margin <= u <= intrinsics.width - margin and margin <= v <= intrinsics.height - margin):
            continue
        found.append(q)
    if len(found) < count:
        raise RuntimeError(f"only {len(found)} of {count} calibration poses found in {settings.max_draw} draws: "
                           "widen 'spread' or the cup limits in config/calibration.yaml")
    # Greedy nearest-neighbour tour in joint space: shorter moves, less time.
    tour, left = [found[0]], found[1:]
    while left:
        nearest = int(np.argmin([np.max(np.abs(q - tour[-1])) for q in left]))
        tour.append(left.pop(nearest))
    return tour


class CalibrationMove:
    """One slow, gated move to a configuration, a control period at a time.

    :param robot: limits, velocity limits, kinematics.
    :param env_cfg: the safety zone and the control period.
    :param guard: the policy node's motion guard settings (``guard`` of config/policy_node.yaml);
        ``start_speed`` is replaced by ``speed``.
    :param speed: rad/s of the slowest-joint-synchronised move.
    :param arrival: rad from the target (every joint) at which it has arrived ...
    :param settle_speed: ... once no joint moves faster than this (rad/s).
    :param control_dt: s per command.
    """

    def __init__(self, robot: RobotSpec, env_cfg: EnvConfig, guard: MotionGuardSettings, speed: float,
                 arrival: float, settle_speed: float, control_dt: float) -> None:
        self.robot = robot
        self.settings = dataclasses.replace(guard, start_speed=speed, start_arrival=arrival,
                                            start_settle_speed=settle_speed, go_to_start=True)
        self.control_dt = control_dt
        self.gate = SafetyGate(robot, control_dt, SafetyZone(robot, env_cfg))
        self.guard: Optional[MotionGuard] = None

    def start(self, target: Sequence[float]) -> None:
        """Begin a move to ``target`` (rad, j1..j6)."""
        self.guard = MotionGuard(self.robot, self.settings, target, 0.0, self.control_dt)

    def step(self, measured: Sequence[float], velocities: Optional[Sequence[float]], now: float
             ) -> Tuple[Optional[np.ndarray], Optional[str]]:
        """``(command, None)`` to send this period, ``(None, None)`` when arrived and at rest, or
        ``(None, why)`` when the safety gate refuses the command (stop: send nothing more).

        :param measured: rad, the newest joint positions. :param velocities: rad/s, if known.
        :param now: s, monotonic.
        """
        if self.guard is None:
            raise RuntimeError("CalibrationMove.step before start")
        targets, refusal = self.guard.start_move(measured, velocities)
        if refusal is not None:
            return None, refusal
        if targets is None:
            return None, None
        command = self.guard.limit(targets, measured, now)
        why = self.gate.check(command, measured)
        return (None, f"safety gate: {why}") if why is not None else (command, None)
