"""The pinhole camera model the simulated camera renders with and the detector back-projects
through (no ROS, no pybullet).

Conventions are those of ``sensor_msgs/CameraInfo`` and REP 103: points in the *optical* frame
(z forward, x right, y down, metres); pixel (u, v) with u along the image columns and the
centre of the top-left pixel at (0, 0); no distortion (a RealSense's colour stream, rectified,
as ``plumb_bob`` with zero coefficients).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Sequence, Tuple

import numpy as np


class IntrinsicsError(ValueError):
    """A camera model that cannot be used (zero or non-finite focal length, bad size)."""


@dataclass(frozen=True)
class Intrinsics:
    """A distortion-free pinhole camera.

    :param width: image width in pixels.
    :param height: image height in pixels.
    :param fx: focal length along u, pixels.
    :param fy: focal length along v, pixels.
    :param cx: principal point u, pixels (top-left pixel centre = 0).
    :param cy: principal point v, pixels.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy)
        if self.width <= 0 or self.height <= 0:
            raise IntrinsicsError(f"image size {self.width}x{self.height} must be positive")
        if not all(np.isfinite(values)) or self.fx <= 0.0 or self.fy <= 0.0:
            raise IntrinsicsError(f"focal lengths must be finite and > 0 (fx={self.fx}, fy={self.fy})")

    # ------------------------------------------------------------------ CameraInfo
    @classmethod
    def from_camera_info(cls, width: int, height: int, k: Sequence[float], p: Sequence[float] = ()) -> "Intrinsics":
        """From a CameraInfo's size, ``K`` (row-major 3x3) and, when set, ``P`` (3x4).

        For a rectified image ``P``'s left 3x3 is the model that applies (image_geometry's
        ``PinholeCameraModel`` projects with ``P``), so it wins over ``K`` when non-zero.

        :raise IntrinsicsError: missing (all-zero) or unusable matrices.
        """
        if len(k) != 9:
            raise IntrinsicsError(f"K must have 9 values, got {len(k)}")
        source = [float(v) for v in k]
        if len(p) == 12 and any(float(v) != 0.0 for v in p):
            source = [float(p[0]), float(p[1]), float(p[2]), float(p[4]), float(p[5]), float(p[6]),
                      float(p[8]), float(p[9]), float(p[10])]
        if not any(source):
            raise IntrinsicsError("camera_info K and P are all zero (an uncalibrated camera)")
        return cls(int(width), int(height), source[0], source[4], source[2], source[5])

    def k(self) -> List[float]:
        """``CameraInfo.K``, row-major."""
        return [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]

    def p(self) -> List[float]:
        """``CameraInfo.P`` of a monocular camera, row-major 3x4."""
        return [self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0]

    # ------------------------------------------------------------------ projection
    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of points (..., 3) in the optical frame (m); z must be > 0."""
        points = np.asarray(points, dtype=float)
        z = points[..., 2]
        return np.stack([self.fx * points[..., 0] / z + self.cx, self.fy * points[..., 1] / z + self.cy], axis=-1)

    def ray(self, u: np.ndarray, v: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """x/z and y/z of the rays through pixels (u, v): a point at depth z is (x z, y z, z)."""
        return (np.asarray(u, dtype=float) - self.cx) / self.fx, (np.asarray(v, dtype=float) - self.cy) / self.fy

    def back_project(self, u: np.ndarray, v: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Points (..., 3) in the optical frame (m) of pixels (u, v) at depth ``depth`` (m, along z)."""
        x, y = self.ray(u, v)
        depth = np.asarray(depth, dtype=float)
        return np.stack([x * depth, y * depth, depth], axis=-1)

    def opengl_projection(self, near: float, far: float) -> np.ndarray:
        """The 4x4 OpenGL projection (eye frame: x right, y up, looking along -z) that renders
        exactly this model into a ``width`` x ``height`` image whose row 0 is the top.

        OpenGL samples pixel centres at half-integers, ROS at integers: the principal point
        moves by half a pixel.
        """
        w, h = float(self.width), float(self.height)
        cx, cy = self.cx + 0.5, self.cy + 0.5
        return np.array([
            [2.0 * self.fx / w, 0.0, 1.0 - 2.0 * cx / w, 0.0],
            [0.0, 2.0 * self.fy / h, 2.0 * cy / h - 1.0, 0.0],
            [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)],
            [0.0, 0.0, -1.0, 0.0],
        ])


# The optical frame in the ROS camera body frame (camera_link: x forward, y left, z up), REP 103.
OPTICAL_IN_CAMERA_LINK_RPY = (-np.pi / 2.0, 0.0, -np.pi / 2.0)
