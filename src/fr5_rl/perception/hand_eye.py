"""Hand-eye calibration of a fixed ("eye-to-hand") camera from a cup held in the gripper (numpy
only: no ROS, no pybullet; scipy is not among the project's dependencies, so the small
least-squares problems here are solved by :func:`levenberg_marquardt`).

The feature is a point fixed in the tcp frame: the centre ``o`` of the cup the closed gripper
holds. At pose ``i`` the arm's forward kinematics gives the tcp pose ``T_tcp_i`` in base_link
and the camera measures the cup centre ``m_i`` in its optical frame. With the camera's own,
factory-known chain ``T_link_opt`` (camera_link -> optical frame, config/camera_frames.yaml),
the unknown mount ``T_base_link`` (base_link -> camera_link, 6 dof) and ``o`` (3) satisfy

    m_i = (T_base_link · T_link_opt)^-1 · T_tcp_i · o          (3 equations per pose)

solved by nonlinear least squares (:func:`solve_hand_eye`) from the configured mount.

Why the poses must vary the tcp orientation, by tilts *and* yaw: a pure translation of the tcp
moves ``T_tcp_i · o`` exactly as it moves the tcp, so any ``o`` fits with a suitably shifted
camera, the two are confounded. A rotation about one axis only leaves the component of ``o``
along that axis unobservable for the same reason (it never changes direction in base_link).
Rotations about two or more axes pin all of ``o``, and then the positions fix the mount.
:func:`check_pose_set` refuses sets that violate this before (or instead of) solving, and the
solve itself refuses an ill-conditioned Jacobian.

The cup's centre is measured by :func:`fit_cylinder_centre`: a closed cylinder of the cup's
known radius and height fitted to the depth points of the cup's colour. The table-top detector
(:mod:`fr5_rl.perception.detector`) cannot be used as it is: it refuses, by design, a piece that
touches the gripper (``OCCLUDED``), and its centre (top face minus half the height along the
table's z) holds for an upright object only; the fitted cylinder's centre is the same point of
the cup from any view and tilt.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import yaml

from ..config import ConfigError, RobotSpec, check_positive, load_typed
from ..kinematics import ForwardKinematics, rotation_from_rpy
from .camera_model import Intrinsics


class CalibrationRefused(ValueError):
    """The data cannot give a trustworthy calibration; the message says what to change."""


@dataclass(frozen=True)
class CupSettings:
    """``cup`` of ``config/calibration.yaml``: the feature.

    :param radius: m. :param height: m.
    :param color: rgb (0-255) of the cup.
    :param chroma_tolerance: largest distance of a pixel's normalised chromaticity from the cup's.
    :param min_pixels: fewer cup pixels: no measurement.
    :param min_cap_pixels: fewer of them on an end face (the top, seen from above): no
        measurement, since the side alone leaves the centre free to slide along the axis (the
        gripper hides the top when it leans toward the camera).
    :param axis_in_tcp: the cup's axis (unit vector) in the tcp frame, the fit's start.
    :param fit_tolerance: m, the soft-L1 scale of the fit's residuals.
    """

    radius: float
    height: float
    color: List[float]
    chroma_tolerance: float
    min_pixels: int
    min_cap_pixels: int
    axis_in_tcp: List[float]
    fit_tolerance: float

    def check(self, source: str) -> None:
        check_positive(source, **{"cup.radius": self.radius, "cup.height": self.height,
                                  "cup.chroma_tolerance": self.chroma_tolerance,
                                  "cup.fit_tolerance": self.fit_tolerance})
        if len(self.color) != 3 or len(self.axis_in_tcp) != 3 or np.linalg.norm(self.axis_in_tcp) < 1e-6:
            raise ConfigError(f"{source}: 'cup.color' needs 3 values and 'cup.axis_in_tcp' a non-zero 3-vector")


@dataclass(frozen=True)
class SimulatorHold:
    """``simulator`` of ``config/calibration.yaml``: the simulated hand-over.

    :param object_in_tcp: m, the cup centre in the tcp frame while the simulator holds it.
    """

    object_in_tcp: List[float]

    def check(self, source: str) -> None:
        if len(self.object_in_tcp) != 3 or not np.all(np.isfinite(self.object_in_tcp)):
            raise ConfigError(f"{source}: 'simulator.object_in_tcp' needs 3 finite values (m)")


@dataclass(frozen=True)
class CalibrationSettings:
    """``config/calibration.yaml`` (every default lives there; see its comments for units)."""

    poses: int
    min_poses: int
    seed: int
    centre_tcp: List[float]  # m, base_link: the tcp at the centre of the poses, gripper straight down
    centre_yaw: float  # rad, the tcp's x axis there from base x, about base z
    spread: List[float]
    max_tilt: float
    min_cup_clearance: float
    max_cup_height: float
    image_margin: int
    max_draw: int
    move_speed: float
    arrival: float
    settle_speed: float
    settle_time: float
    frames_per_pose: int
    frame_timeout: float
    move_timeout: float
    cup: CupSettings
    min_position_spread: float
    min_rotation_spread: float
    max_residual: float
    max_condition: float
    base_frame: str
    mount_frame: str
    frames_config: str
    optical_frame: str
    mount_config: str
    joint_states_topic: str
    command_topic: str
    color_topic: str
    depth_topic: str
    camera_info_topic: str
    sim_hold_service: str
    control_rate: float
    simulator: SimulatorHold

    def check(self, source: str) -> None:
        if self.min_poses < 4 or self.poses < 1:
            raise ConfigError(f"{source}: 'min_poses' must be >= 4 (9 unknowns, 3 equations a pose) and 'poses' >= 1")
        if len(self.centre_tcp) != 3 or len(self.spread) != 6:
            raise ConfigError(f"{source}: 'centre_tcp' needs 3 values (m, base_link) and 'spread' 6 (rad, j1..j6)")
        check_positive(source, move_speed=self.move_speed, arrival=self.arrival, settle_speed=self.settle_speed,
                       settle_time=self.settle_time, frames_per_pose=self.frames_per_pose,
                       frame_timeout=self.frame_timeout, move_timeout=self.move_timeout,
                       control_rate=self.control_rate, max_condition=self.max_condition)
        if self.move_speed > 0.3:
            raise ConfigError(f"{source}: 'move_speed' {self.move_speed} rad/s: calibration moves are slow ones, "
                              "at most 0.3 rad/s (the motion guard's start move cap)")


def load_calibration_settings(path_or_name: str | Path = "calibration") -> CalibrationSettings:
    """``config/calibration.yaml`` (or another file: a path or a name in ``config/``), checked."""
    return load_typed(CalibrationSettings, path_or_name)


# ---------------------------------------------------------------------------- rotations
def rotation_from_vector(vector: Sequence[float]) -> np.ndarray:
    """Rodrigues: 3x3 rotation of the rotation vector ``vector`` (axis * angle, rad)."""
    w = np.asarray(vector, dtype=np.float64)
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        return np.eye(3) + k
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) / angle
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def vector_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """The rotation vector (axis * angle, rad, angle in [0, pi]) of a 3x3 rotation."""
    r = np.asarray(rotation, dtype=np.float64)
    cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    angle = math.acos(cos)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-9:
        return 0.5 * axis
    if angle > math.pi - 1e-6:  # sin ~ 0: the axis from the symmetric part
        values, vectors = np.linalg.eigh((r + np.eye(3)) / 2.0)
        return vectors[:, int(np.argmax(values))] * angle
    return axis / (2.0 * math.sin(angle)) * angle


def rpy_from_rotation(rotation: np.ndarray) -> Tuple[float, float, float]:
    """URDF fixed-axis roll, pitch, yaw (rad) of a 3x3 rotation (R = Rz(yaw) Ry(pitch) Rx(roll)),
    the inverse of :func:`fr5_rl.kinematics.rotation_from_rpy`."""
    r = np.asarray(rotation, dtype=np.float64)
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.cos(pitch) > 1e-9:
        roll, yaw = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: put it all in yaw
        roll, yaw = 0.0, math.atan2(-r[0, 1], r[1, 1])
    return roll, pitch, yaw


def transform_error(estimate: np.ndarray, truth: np.ndarray) -> Tuple[float, float]:
    """(translation error m, rotation error rad) between two 4x4 poses in the same parent."""
    rotation = np.asarray(estimate)[:3, :3].T @ np.asarray(truth)[:3, :3]
    return (float(np.linalg.norm(np.asarray(estimate)[:3, 3] - np.asarray(truth)[:3, 3])),
            float(np.linalg.norm(vector_from_rotation(rotation))))


def offset_transform(offset: Sequence[float]) -> np.ndarray:
    """4x4 of a mount offset ``(dx, dy, dz, droll, dpitch, dyaw)`` (m, rad; URDF fixed-axis rpy)."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotation_from_rpy(*offset[3:6])
    matrix[:3, 3] = offset[:3]
    return matrix


# ---------------------------------------------------------------------------- least squares
def numeric_jacobian(residual: Callable[[np.ndarray], np.ndarray], x: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian (m, n) of ``residual`` at ``x`` (n parameters)."""
    columns = [(residual(x + step * e) - residual(x - step * e)) / (2.0 * step) for e in np.eye(len(x))]
    return np.array(columns).T


def levenberg_marquardt(residual: Callable[[np.ndarray], np.ndarray], x0: Sequence[float],
                        robust_scale: float = 0.0, iterations: int = 100, tolerance: float = 1e-12) -> np.ndarray:
    """Minimise ``sum(rho(residual(x)^2))`` from ``x0`` by Levenberg-Marquardt (numeric Jacobian).

    :param robust_scale: > 0: soft-L1 loss of that scale (residual units), by iteratively
        reweighted least squares; 0: plain least squares.
    :param tolerance: stop when a step changes the cost relatively less than this.
    :return: the parameters at the minimum.
    """
    x = np.asarray(x0, dtype=np.float64).copy()

    def weighted(r: np.ndarray) -> np.ndarray:
        if robust_scale <= 0.0:
            return r
        # soft-L1: rho(s) = 2 (sqrt(1 + s) - 1), s = (r / c)^2; IRLS weight rho'(s) = 1 / sqrt(1 + s).
        return r * (1.0 + (r / robust_scale) ** 2) ** -0.25

    def cost(r: np.ndarray) -> float:
        if robust_scale <= 0.0:
            return float(r @ r)
        return float(np.sum(2.0 * robust_scale ** 2 * (np.sqrt(1.0 + (r / robust_scale) ** 2) - 1.0)))

    damping = 1e-3
    current = residual(x)
    for _ in range(iterations):
        jacobian = numeric_jacobian(residual, x)
        if robust_scale > 0.0:
            scale = (1.0 + (current / robust_scale) ** 2) ** -0.25
            jacobian = jacobian * scale[:, None]
        r = weighted(current)
        normal, gradient = jacobian.T @ jacobian, jacobian.T @ r
        improved = False
        for _ in range(20):
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -gradient)
            candidate = x + step
            trial = residual(candidate)
            if cost(trial) < cost(current):
                change = (cost(current) - cost(trial)) / max(cost(current), 1e-300)
                x, current, improved = candidate, trial, True
                damping = max(damping / 3.0, 1e-12)
                break
            damping *= 4.0
        if not improved or change < tolerance:
            break
    return x


# ---------------------------------------------------------------------------- the solve
@dataclass(frozen=True)
class HandEyeResult:
    """A solved calibration.

    :param base_from_mount: 4x4 pose of camera_link in base_link (m).
    :param object_in_tcp: the cup centre in the tcp frame (m).
    :param residuals: (N, 3) measured minus modelled cup centre, optical frame (m), per pose.
    :param condition: condition number of the scaled Jacobian at the solution.
    :param smallest_singular: its smallest singular value (m per m or rad).
    """

    base_from_mount: np.ndarray
    object_in_tcp: np.ndarray
    residuals: np.ndarray
    condition: float
    smallest_singular: float

    @property
    def rms_mm(self) -> float:
        """RMS of the per-pose residual distances (mm)."""
        return float(np.sqrt(np.mean(np.sum(self.residuals ** 2, axis=1)))) * 1e3

    @property
    def max_mm(self) -> float:
        """Largest per-pose residual distance (mm)."""
        return float(np.max(np.linalg.norm(self.residuals, axis=1))) * 1e3


def _model(params: np.ndarray, start: np.ndarray, mount_from_optical: np.ndarray,
           tcp_poses: np.ndarray) -> np.ndarray:
    """Modelled cup centres (N, 3) in the optical frame. ``params``: translation of camera_link
    (m, base_link), rotation vector (rad) applied on the right of the start's rotation (a
    perturbation in the camera_link frame, small and well scaled), cup centre in tcp (m)."""
    mount = np.eye(4)
    mount[:3, :3] = start[:3, :3] @ rotation_from_vector(params[3:6])
    mount[:3, 3] = params[:3]
    base_from_optical = mount @ mount_from_optical
    rotation, origin = base_from_optical[:3, :3], base_from_optical[:3, 3]
    cup_base = np.einsum("nij,j->ni", tcp_poses[:, :3, :3], params[6:9]) + tcp_poses[:, :3, 3]
    return (cup_base - origin) @ rotation


def _mount(params: np.ndarray, start: np.ndarray) -> np.ndarray:
    mount = np.eye(4)
    mount[:3, :3] = start[:3, :3] @ rotation_from_vector(params[3:6])
    mount[:3, 3] = params[:3]
    return mount


def check_pose_set(tcp_poses: np.ndarray, min_poses: int, min_position_spread: float,
                   min_rotation_spread: float, object_in_tcp: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
    """Refuse a pose set that cannot determine the mount and the cup offset.

    :param tcp_poses: (N, 4, 4) tcp poses in base_link (m).
    :param min_poses: fewest usable poses.
    :param min_position_spread: m, smallest allowed second principal spread (std) of the cup
        positions (near-collinear positions leave the rotation about their line free).
    :param min_rotation_spread: rad, smallest allowed second principal spread of the tcp
        rotations (relative to their first): rotations about one axis only leave the cup
        offset along it confounded with the mount.
    :param object_in_tcp: m, the cup centre's (assumed) offset in the tcp frame.
    :raises CalibrationRefused: with what to change.
    """
    poses = np.asarray(tcp_poses, dtype=np.float64)
    count = len(poses)
    if count < min_poses:
        raise CalibrationRefused(f"{count} usable pose(s), at least {min_poses} needed: "
                                 f"{min_poses - count} more")
    points = np.einsum("nij,j->ni", poses[:, :3, :3], np.asarray(object_in_tcp, dtype=np.float64)) + poses[:, :3, 3]
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False) / math.sqrt(count)
    if spread[1] < min_position_spread:
        raise CalibrationRefused(f"the cup positions are near-collinear (spreads {spread[0] * 1e3:.0f}, "
                                 f"{spread[1] * 1e3:.1f}, {spread[2] * 1e3:.1f} mm; the second must be >= "
                                 f"{min_position_spread * 1e3:.0f} mm): spread the poses over a plane or a volume")
    reference = poses[0, :3, :3]
    vectors = np.array([vector_from_rotation(reference.T @ pose[:3, :3]) for pose in poses])
    turns = np.linalg.svd(vectors - vectors.mean(axis=0), compute_uv=False) / math.sqrt(count)
    if turns[1] < min_rotation_spread:
        raise CalibrationRefused(f"the tcp orientation does not vary enough (rotation spreads "
                                 f"{math.degrees(turns[0]):.1f}, {math.degrees(turns[1]):.1f}, "
                                 f"{math.degrees(turns[2]):.1f} deg; the second must be >= "
                                 f"{math.degrees(min_rotation_spread):.1f} deg): vary the tilts (j4, j5) and "
                                 "the yaw (j6) of the tcp, about two axes at least")


def jacobian_conditioning(params: np.ndarray, start: np.ndarray, mount_from_optical: np.ndarray,
                          tcp_poses: np.ndarray) -> Tuple[float, float]:
    """(condition number, smallest singular value) of the model's Jacobian at ``params``
    (central differences). Rotations are in rad and translations in m: at the ~1 m between
    camera and cup, 1 rad moves the model about as much as 1 m, so the columns need no scaling."""
    jacobian = numeric_jacobian(lambda x: _model(x, start, mount_from_optical, tcp_poses).ravel(),
                                np.asarray(params, dtype=np.float64))
    singular = np.linalg.svd(jacobian, compute_uv=False)
    smallest = float(singular[-1])
    return (float(singular[0] / smallest) if smallest > 0 else math.inf), smallest


def solve_hand_eye(tcp_poses: np.ndarray, measured: np.ndarray, start_mount: np.ndarray,
                   mount_from_optical: np.ndarray, max_condition: float,
                   object_start: Sequence[float] = (0.0, 0.0, 0.0)) -> HandEyeResult:
    """Least-squares mount and cup offset.

    :param tcp_poses: (N, 4, 4) tcp poses in base_link (m), from forward kinematics.
    :param measured: (N, 3) cup centres in the optical frame (m).
    :param start_mount: 4x4 configured base_link -> camera_link (m), the start.
    :param mount_from_optical: 4x4 camera_link -> optical frame (the camera's own chain).
    :param max_condition: a larger condition number of the Jacobian is refused.
    :param object_start: m, the cup offset in tcp to start from.
    :raises CalibrationRefused: the problem is ill-conditioned (says the numbers and what to vary).
    """
    poses, measured = np.asarray(tcp_poses, dtype=np.float64), np.asarray(measured, dtype=np.float64)
    start = np.asarray(start_mount, dtype=np.float64)
    x0 = np.concatenate([start[:3, 3], np.zeros(3), np.asarray(object_start, dtype=np.float64)])

    def residual(x: np.ndarray) -> np.ndarray:
        return (_model(x, start, mount_from_optical, poses) - measured).ravel()

    condition, smallest = jacobian_conditioning(x0, start, mount_from_optical, poses)
    if condition > max_condition:
        raise CalibrationRefused(f"the pose set is degenerate: Jacobian condition number {condition:.3g} "
                                 f"(> {max_condition:g}), smallest singular value {smallest:.3g}: vary the tcp "
                                 "tilts and yaw and spread the cup positions over a volume")
    # A robust loss would hide a bad pose in the fit; plain least squares reports it in the
    # residual instead (max), where the user can see it.
    solution = levenberg_marquardt(residual, x0)
    condition, smallest = jacobian_conditioning(solution, start, mount_from_optical, poses)
    if condition > max_condition:
        raise CalibrationRefused(f"the solution is ill-conditioned: Jacobian condition number {condition:.3g} "
                                 f"(> {max_condition:g}), smallest singular value {smallest:.3g}: vary the tcp "
                                 "tilts and yaw and spread the cup positions over a volume")
    # residual = model - measured; report measured - model.
    return HandEyeResult(_mount(solution, start), solution[6:9].copy(),
                         -residual(solution).reshape(-1, 3), condition, smallest)


def solve_rejecting_outliers(tcp_poses: np.ndarray, measured: np.ndarray, start_mount: np.ndarray,
                             mount_from_optical: np.ndarray, max_condition: float, min_poses: int,
                             max_residual: float) -> Tuple[HandEyeResult, List[int]]:
    """:func:`solve_hand_eye`, then, while a pose's residual exceeds ``max_residual`` (m) and more
    than ``min_poses`` are left, drop the worst pose and solve again: a measurement spoilt by
    an occlusion the checks missed would otherwise pull every other pose's fit.

    :return: the result on the kept poses and the indices of the dropped ones.
    """
    keep = list(range(len(measured)))
    dropped: List[int] = []
    while True:
        result = solve_hand_eye(tcp_poses[keep], measured[keep], start_mount, mount_from_optical, max_condition)
        errors = np.linalg.norm(result.residuals, axis=1)
        worst = int(np.argmax(errors))
        if errors[worst] <= max_residual or len(keep) <= min_poses:
            return result, dropped
        dropped.append(keep.pop(worst))


def tcp_poses_from_joints(robot: RobotSpec, joints: Sequence[Sequence[float]]) -> np.ndarray:
    """(N, 4, 4) tcp poses in base_link from measured arm joint positions (rad, j1..j6),
    by the project's forward kinematics."""
    kinematics = ForwardKinematics(robot)
    poses = np.tile(np.eye(4), (len(joints), 1, 1))
    for pose, q in zip(poses, joints):
        position, rotation = kinematics.tcp_pose(np.asarray(q, dtype=np.float64))
        pose[:3, :3], pose[:3, 3] = rotation, position
    return poses


# ---------------------------------------------------------------------------- the measurement
def cup_mask(color: np.ndarray, depth: np.ndarray, cup: CupSettings) -> np.ndarray:
    """Pixels (H, W bool) of the cup's colour with valid depth: normalised chromaticity within
    ``cup.chroma_tolerance`` of the cup's, so shading does not matter."""
    rgb = np.asarray(color, dtype=np.float32)
    total = rgb.sum(axis=2) + 1e-3
    target = np.asarray(cup.color, dtype=np.float32)
    target = target / target.sum()
    distance = np.hypot(rgb[..., 0] / total - target[0], rgb[..., 1] / total - target[1])
    # Dark pixels have no reliable chromaticity.
    return (distance <= cup.chroma_tolerance) & (total > 60.0) & (np.asarray(depth) > 0)


def _cylinder_distance(points: np.ndarray, centre: np.ndarray, axis: np.ndarray, radius: float,
                       half_height: float) -> np.ndarray:
    """Signed distance (m) of points to a closed cylinder's surface (negative inside)."""
    relative = points - centre
    along = relative @ axis
    radial = np.linalg.norm(relative - np.outer(along, axis), axis=1)
    q_radial, q_axial = radial - radius, np.abs(along) - half_height
    outside = np.hypot(np.maximum(q_radial, 0.0), np.maximum(q_axial, 0.0))
    return np.where((q_radial > 0) | (q_axial > 0), outside, np.maximum(q_radial, q_axial))


def fit_cylinder_centre(points: np.ndarray, axis_guess: Sequence[float], cup: CupSettings
                        ) -> Tuple[np.ndarray, int]:
    """Centre (m) of the cup in the points' frame: a closed cylinder of the cup's radius and
    height fitted to its visible surface points (robust soft-L1 loss; the axis refined from
    ``axis_guess``). The centre of the visible points is not the cup's (it leans toward the
    camera by a view-dependent amount); the fitted solid's centre is the same point from any
    view.

    :param points: (n, 3) surface points of the cup (m), e.g. the optical frame.
    :param axis_guess: the cup's axis in that frame (either sign; the cylinder is symmetric).
    :return: the centre, and how many points lie on an end face (within 2 ``fit_tolerance``).
    """
    points = np.asarray(points, dtype=np.float64)
    axis0 = np.asarray(axis_guess, dtype=np.float64)
    axis0 = axis0 / np.linalg.norm(axis0)
    helper = np.eye(3)[int(np.argmin(np.abs(axis0)))]
    u = np.cross(axis0, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis0, u)
    mean = points.mean(axis=0)
    # Start behind the visible surface: the camera sees the near side.
    centre0 = mean + mean / np.linalg.norm(mean) * cup.radius * 0.5

    def unpack(x: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        axis = axis0 + x[3] * u + x[4] * v
        return x[:3], axis / np.linalg.norm(axis)

    def residual(x: np.ndarray) -> np.ndarray:
        centre, axis = unpack(x)
        return _cylinder_distance(points, centre, axis, cup.radius, cup.height / 2.0)

    solution = levenberg_marquardt(residual, np.concatenate([centre0, [0.0, 0.0]]),
                                   robust_scale=cup.fit_tolerance, tolerance=1e-10)
    centre, axis = unpack(solution)
    relative = points - centre
    along = relative @ axis
    radial = np.linalg.norm(relative - np.outer(along, axis), axis=1)
    on_cap = (np.abs(np.abs(along) - cup.height / 2.0) < 2.0 * cup.fit_tolerance) & (radial < cup.radius - cup.fit_tolerance)
    return centre, int(on_cap.sum())


def measure_cup(color: np.ndarray, depth_m: np.ndarray, intrinsics: Intrinsics, axis_guess: Sequence[float],
                cup: CupSettings) -> Optional[np.ndarray]:
    """The held cup's centre (m) in the image's optical frame, or None when fewer than
    ``cup.min_pixels`` of its pixels show or fewer than ``cup.min_cap_pixels`` of its top.

    :param color: (H, W, 3) uint8 rgb.
    :param depth_m: (H, W) depth along the optical axis (m, 0 = none), aligned to colour.
    :param intrinsics: the pinhole model of the images (the detector's).
    :param axis_guess: the cup's axis in the optical frame (from the configured mount and FK).
    """
    mask = cup_mask(color, depth_m, cup)
    if int(mask.sum()) < cup.min_pixels:
        return None
    v, u = np.nonzero(mask)
    points = intrinsics.back_project(u.astype(np.float64), v.astype(np.float64), np.asarray(depth_m)[v, u])
    centre, cap = fit_cylinder_centre(points, axis_guess, cup)
    return centre if cap >= cup.min_cap_pixels else None


# ---------------------------------------------------------------------------- the result file
def calibrated_transforms_yaml(entries: Sequence[Dict], parent: str, child: str, base_from_mount: np.ndarray,
                               comment: str) -> str:
    """The transforms file (config/static_transforms.yaml's format) with the ``parent -> child``
    entry set to ``base_from_mount`` (xyz m, URDF rpy rad) and every other entry kept.

    :param entries: :func:`fr5_rl.transforms.load_static_transforms` entries of the configured file.
    :param comment: header lines (without '#') saying how it was made.
    :raises ConfigError: the file has no ``parent -> child`` entry.
    """
    if not any(entry["parent"] == parent and entry["child"] == child for entry in entries):
        raise ConfigError(f"the transforms file has no {parent} -> {child} entry to calibrate")
    items = []
    for entry in entries:
        if entry["parent"] == parent and entry["child"] == child:
            xyz = [round(float(v), 6) for v in base_from_mount[:3, 3]]
            rpy = [round(float(v), 6) for v in rpy_from_rotation(base_from_mount[:3, :3])]
        else:
            xyz = [float(v) for v in entry["xyz"]]
            rpy = [float(v) for v in entry["rpy"]]
        items.append({"parent": entry["parent"], "child": entry["child"], "xyz": xyz, "rpy": rpy})
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    header += "# xyz in metres, rpy in radians (URDF convention: fixed-axis roll, pitch, yaw).\n"
    return header + yaml.safe_dump({"transforms": items}, default_flow_style=None, sort_keys=False)


def write_result(path: Path, text: str, force: bool) -> None:
    """Write ``text`` to ``path``; an existing file is kept unless ``force``.

    :raises CalibrationRefused: the file exists and ``force`` is false.
    """
    if path.exists() and not force:
        raise CalibrationRefused(f"{path} exists: pass --force to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
