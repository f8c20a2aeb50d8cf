"""Forward kinematics of a FAIRINO arm from its joint-origin table (``config/robots/<model>.yaml``).

The environments and the ROS policy node both compute the tcp pose with this code from
measured joint angles, so the observation cannot differ between training and deployment.
All poses are expressed in ``base_link``; positions in metres.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .config import RobotSpec

try:
    # np.linalg.solve's own kernel, without its per-call checks and conversions (3.4 of its
    # 4.9 us for a 6x6 system): the same LAPACK call, the same bits. The systems solved with it
    # here are symmetric positive definite (damped normal equations): the checks catch nothing.
    from numpy.linalg._umath_linalg import solve1 as solve_linear
except ImportError:  # a numpy that moved it: the public call, a little slower
    solve_linear = np.linalg.solve


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw (rad) to a 3x3 rotation: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


class ForwardKinematics:
    """Flange and tcp poses of the FR5 in ``base_link`` for given joint angles (rad)."""

    def __init__(self, robot: RobotSpec) -> None:
        self._origin_rotations = [rotation_from_rpy(*rpy) for rpy in robot.joint_origins_rpy]
        self._origin_translations = [np.asarray(xyz, dtype=np.float64) for xyz in robot.joint_origins_xyz]
        # The tcp from the last joint's frame (the wrist centre): the flange face, then the tool.
        self._tcp_offset = float(robot.tcp_offset_from_wrist)
        self._flange_offset = float(robot.flange_offset)
        # The same table as plain floats (rotation row-major, then translation): flange_pose runs
        # for every observation, where numpy's per-call cost on 3x3 matrices dominates.
        self._origins_flat = [tuple(float(v) for v in rotation.ravel()) + tuple(float(v) for v in translation)
                              for rotation, translation in zip(self._origin_rotations, self._origin_translations)]

    def _chain(self, joint_positions: Sequence[float], joints: Optional[list] = None) -> Tuple[float, ...]:
        """The flange pose as 12 floats: position, then rotation row-major. With ``joints``, also
        appends each joint's origin and axis there (6 floats each, base_link).

        Each joint: position += R @ origin translation, then R = R @ origin rotation @ Rz(angle).
        """
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px = py = pz = 0.0
        for (o00, o01, o02, o10, o11, o12, o20, o21, o22, tx, ty, tz), angle in zip(
            self._origins_flat, joint_positions
        ):
            px += r00 * tx + r01 * ty + r02 * tz
            py += r10 * tx + r11 * ty + r12 * tz
            pz += r20 * tx + r21 * ty + r22 * tz
            c, s = math.cos(angle), math.sin(angle)
            # M = origin rotation @ Rz(angle): its first two columns turn, the third stays.
            m00, m01 = o00 * c + o01 * s, o01 * c - o00 * s
            m10, m11 = o10 * c + o11 * s, o11 * c - o10 * s
            m20, m21 = o20 * c + o21 * s, o21 * c - o20 * s
            r00, r01, r02 = (r00 * m00 + r01 * m10 + r02 * m20, r00 * m01 + r01 * m11 + r02 * m21,
                             r00 * o02 + r01 * o12 + r02 * o22)
            r10, r11, r12 = (r10 * m00 + r11 * m10 + r12 * m20, r10 * m01 + r11 * m11 + r12 * m21,
                             r10 * o02 + r11 * o12 + r12 * o22)
            r20, r21, r22 = (r20 * m00 + r21 * m10 + r22 * m20, r20 * m01 + r21 * m11 + r22 * m21,
                             r20 * o02 + r21 * o12 + r22 * o22)
            if joints is not None:
                joints.append((px, py, pz, r02, r12, r22))  # the turn about z leaves the axis as it was
        return px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22

    def flange_pose(self, joint_positions: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
        """Return (position (3,), rotation (3, 3)) of the flange frame (the spec's ``flange_frame``:
        the flange face, ``flange_offset`` beyond the wrist centre along j6) in base_link."""
        px, py, pz, *rotation = self._chain(joint_positions)
        rotation = np.array(rotation).reshape(3, 3)
        return np.array((px, py, pz)) + rotation[:, 2] * self._flange_offset, rotation

    def tcp_position_and_axis(self, joint_positions: Sequence[float]) -> Tuple[List[float], List[float]]:
        """The tcp's position (m) and approach axis (its z, unit) in base_link, as plain floats:
        :meth:`tcp_pose` without numpy, for the observation's hot path (the same arithmetic, so
        the same bits).

        :param joint_positions: j1..j6 (rad).
        """
        px, py, pz, _, _, r02, _, _, r12, _, _, r22 = self._chain(joint_positions)
        offset = self._tcp_offset
        return [px + r02 * offset, py + r12 * offset, pz + r22 * offset], [r02, r12, r22]

    def tcp_jacobian(self, joint_positions: Sequence[float]) -> Tuple[List[float], List[float], List[List[float]]]:
        """The tcp's position (m), approach axis (its z, unit) and geometric Jacobian in base_link.

        :param joint_positions: j1..j6 (rad).
        :return: ``(position, approach_axis, jacobian)``, plain floats; ``jacobian`` has six rows
            (tcp linear velocity in m/s, then angular velocity in rad/s) of six columns (per
            rad/s of each joint). Every FR5 joint turns about its own frame's z axis, so column
            ``i`` is ``(axis_i x (tcp - origin_i), axis_i)``.
        """
        position, rotation, jacobian = self.tcp_pose_and_jacobian(joint_positions)
        return position, [rotation[2], rotation[5], rotation[8]], jacobian

    def tcp_pose_and_jacobian(self, joint_positions: Sequence[float]) -> Tuple[List[float], List[float], List[List[float]]]:
        """:meth:`tcp_jacobian` with the whole tcp rotation instead of its approach axis.

        :param joint_positions: j1..j6 (rad).
        :return: ``(position, rotation, jacobian)``: the tcp position (m, base_link), its
            rotation (9 floats, row-major) and the geometric Jacobian (six rows of six).
        """
        joints: list = []
        px, py, pz, *rotation = self._chain(joint_positions, joints)
        offset = self._tcp_offset
        r02, r12, r22 = rotation[2], rotation[5], rotation[8]
        tx, ty, tz = px + r02 * offset, py + r12 * offset, pz + r22 * offset
        linear_x, linear_y, linear_z, angular_x, angular_y, angular_z = [], [], [], [], [], []
        for ox, oy, oz, ax, ay, az in joints:
            dx, dy, dz = tx - ox, ty - oy, tz - oz
            linear_x.append(ay * dz - az * dy)
            linear_y.append(az * dx - ax * dz)
            linear_z.append(ax * dy - ay * dx)
            angular_x.append(ax)
            angular_y.append(ay)
            angular_z.append(az)
        return [tx, ty, tz], rotation, [linear_x, linear_y, linear_z, angular_x, angular_y, angular_z]

    def joint_origins(self, joint_positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Origins of the joint frames j1 … j6 (rows, m, base_link; j6's is the wrist centre) and
        the flange rotation: the points the arm's links run between."""
        rotation = np.eye(3)
        position = np.zeros(3)
        origins = []
        for origin_rotation, origin_translation, angle in zip(
            self._origin_rotations, self._origin_translations, joint_positions
        ):
            position = position + rotation @ origin_translation
            origins.append(position)
            c, s = np.cos(angle), np.sin(angle)
            rotation = rotation @ origin_rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return np.array(origins), rotation

    def tcp_pose(self, joint_positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return (position (3,), rotation (3, 3)) of the ``tcp`` frame in base_link.

        The tcp sits ``tcp_offset`` metres along the flange z axis beyond the flange, with the
        flange's orientation, so its z axis is the gripper's approach direction.
        """
        px, py, pz, *rotation = self._chain(joint_positions)
        rotation = np.array(rotation).reshape(3, 3)
        return np.array((px, py, pz)) + rotation[:, 2] * self._tcp_offset, rotation


class InverseKinematics:
    """Joint angles that put the tcp at a pose: Newton's method on :class:`ForwardKinematics`,
    from a start near the answer (the current joint angles), without PyBullet.

    Each iteration solves the damped normal equations ``dq = J^T (J J^T + damping^2 I)^-1 e``
    for the pose error ``e`` (position, then the rotation vector that turns the tcp's axes onto
    the target's, small-angle form). From a start a few centimetres away it converges in 2-3
    iterations; it finds the solution nearest the start (no null space: six joints, six
    constraints) and neither clamps to nor checks the joint limits.

    :param kinematics: the arm's forward kinematics.
    :param damping: keeps the step bounded near singular poses (m); small enough that it does
        not slow convergence elsewhere.
    """

    def __init__(self, kinematics: ForwardKinematics, damping: float = 1e-4) -> None:
        self._kinematics = kinematics
        self._damping = damping ** 2 * np.eye(6)

    def solve(self, start: Sequence[float], tcp_position: Sequence[float], tcp_rotation: Sequence[float],
              max_iterations: int = 10, tolerance: float = 1e-7) -> Tuple[List[float], bool]:
        """:param start: j1..j6 (rad) to start from.
        :param tcp_position: the wanted tcp position (m, base_link).
        :param tcp_rotation: the wanted tcp rotation in base_link (9 floats, row-major).
        :param max_iterations: most Newton steps.
        :param tolerance: stop once every position (m) and rotation (rad) error is below this.
        :return: ``(joint_positions, converged)``; the last iterate when not converged.
        """
        target_x, target_y, target_z = (float(v) for v in tcp_position)
        t00, t01, t02, t10, t11, t12, t20, t21, t22 = (float(v) for v in tcp_rotation)
        joints = [float(v) for v in start]
        for _ in range(max_iterations):
            (x, y, z), (r00, r01, r02, r10, r11, r12, r20, r21, r22), jacobian = \
                self._kinematics.tcp_pose_and_jacobian(joints)
            # Half the sum of (current axis x target axis) over the three axes: the rotation
            # vector of the error for small angles, and zero only when the axes agree.
            error = (target_x - x, target_y - y, target_z - z,
                     0.5 * ((r10 * t20 - r20 * t10) + (r11 * t21 - r21 * t11) + (r12 * t22 - r22 * t12)),
                     0.5 * ((r20 * t00 - r00 * t20) + (r21 * t01 - r01 * t21) + (r22 * t02 - r02 * t22)),
                     0.5 * ((r00 * t10 - r10 * t00) + (r01 * t11 - r11 * t01) + (r02 * t12 - r12 * t02)))
            if max(abs(value) for value in error) < tolerance:
                return joints, True
            matrix = np.array(jacobian)
            step = matrix.T @ solve_linear(matrix @ matrix.T + self._damping, np.array(error))
            joints = [angle + change for angle, change in zip(joints, step.tolist())]
        return joints, False
