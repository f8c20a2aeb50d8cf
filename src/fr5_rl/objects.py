"""The objects a production line hands the arm: their shape, size and yaw, as the policy sees them.

One convention everywhere (the simulator, the environment's observation, the detector, the
policy node): an object's own frame has z up, and for a box x along its longer top side
(``size[0] >= size[1]``). A yaw is the angle of that x axis in ``base_link``'s xy plane; a
cylinder has none that matters.

The policy sees the object's yaw relative to the gripper's as ``(sin kΔ, cos kΔ)`` with ``k``
the order of the top's symmetry: 4 for a square (it repeats every 90°), 2 for a rectangle (every
180°), 0 for a cylinder (``(0, 0)``: no yaw to match). Two yaws the object cannot tell apart
then read the same, and the encoding has no jump anywhere.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np

SHAPES = ("cylinder", "box")


@dataclass(frozen=True)
class ObjectShape:
    """An object's kind and size.

    :param kind: ``cylinder`` or ``box``.
    :param size: extent (m) along the object's own x, y and z (for a cylinder: diameter,
        diameter, height; for a box ``size[0] >= size[1]``).
    :param square_tolerance: m, top sides closer than this make a square (symmetry 4).
    """

    kind: str
    size: Tuple[float, float, float]
    square_tolerance: float = 0.002

    def __post_init__(self) -> None:
        if self.kind not in SHAPES:
            raise ValueError(f"object kind must be one of {SHAPES}, got {self.kind!r}")
        if len(self.size) != 3 or not all(math.isfinite(s) and s > 0.0 for s in self.size):
            raise ValueError(f"object size must be three positive extents (m), got {self.size!r}")
        if self.kind == "box" and self.size[0] < self.size[1]:
            raise ValueError(f"a box's size lists its longer top side first, got {self.size!r}")

    @classmethod
    def from_dims(cls, kind: str, dims: Sequence[float]) -> "ObjectShape":
        """From the simulator's dimensions: (radius, height) of a cylinder, (half_extent,) of a
        cube, or (half_x, half_y, half_z) of a box."""
        if kind == "cylinder":
            radius, height = dims
            return cls(kind, (2.0 * radius, 2.0 * radius, height))
        if len(dims) == 1:
            return cls(kind, (2.0 * dims[0],) * 3)
        half_x, half_y, half_z = dims
        return cls(kind, (2.0 * half_x, 2.0 * half_y, 2.0 * half_z))

    @property
    def dims(self) -> Tuple[float, ...]:
        """The simulator's dimensions (:meth:`from_dims`): (radius, height) of a cylinder, the
        half extents of a box."""
        x, y, z = self.size
        return (0.5 * x, z) if self.kind == "cylinder" else (0.5 * x, 0.5 * y, 0.5 * z)

    @property
    def symmetry_order(self) -> int:
        """How many times the top repeats in a turn: 0 (a cylinder, any yaw), 4 (a square), 2."""
        if self.kind == "cylinder":
            return 0
        return 4 if self.size[0] - self.size[1] <= self.square_tolerance else 2

    @property
    def label(self) -> str:
        """What a report counts it as: ``cylinder``, ``square box`` or ``rectangular box``."""
        if self.kind == "cylinder":
            return "cylinder"
        return "square box" if self.symmetry_order == 4 else "rectangular box"

    @property
    def grasp_width(self) -> float:
        """m across the object where the fingers close on it: a cylinder's diameter, a box's
        narrower top side."""
        return self.size[1]

    def yaw_features(self, object_yaw: float, gripper_yaw: float) -> Tuple[float, float]:
        """``(sin kΔ, cos kΔ)`` of the object's yaw relative to the gripper's (rad, base_link),
        ``k`` the symmetry order; ``(0, 0)`` for a cylinder."""
        order = self.symmetry_order
        if order == 0:
            return 0.0, 0.0
        relative = order * (object_yaw - gripper_yaw)
        return math.sin(relative), math.cos(relative)

    def yaw_error(self, yaw: float, goal_yaw: float) -> float:
        """|yaw - goal_yaw| (rad) modulo the top's symmetry, in [0, pi / k]; 0 for a cylinder."""
        order = self.symmetry_order
        if order == 0:
            return 0.0
        period = 2.0 * math.pi / order
        error = (yaw - goal_yaw) % period
        return min(error, period - error)


def shape_from_extents(kind: str, extents: Sequence[float]) -> Tuple[ObjectShape, float]:
    """An object's shape from extents along a frame of its own (m: x, y, z; a cylinder's x and y
    are its diameter), and the turn (rad) from that frame's x axis to the shape's: for a box whose
    y side is the longer, the convention's x is that frame's y (``pi / 2``), else 0.

    :raises ValueError: an unknown kind or extents that are not three positive lengths.
    """
    if kind == "box" and len(extents) == 3 and extents[1] > extents[0]:
        return ObjectShape(kind, (float(extents[1]), float(extents[0]), float(extents[2]))), math.pi / 2.0
    return ObjectShape(kind, tuple(float(e) for e in extents)), 0.0


def distance_to_upright_object(point: Sequence[float], centre: Sequence[float], half_height: float) -> float:
    """m from ``point`` to an upright object's axis, the segment from its bottom to its top (its
    centre ``centre`` plus or minus ``half_height``; all m, one frame with z up). A tcp that
    grasps a tall object near its top is near the object, however far above its centre.
    """
    horizontal = math.hypot(point[0] - centre[0], point[1] - centre[1])
    vertical = max(0.0, abs(point[2] - centre[2]) - half_height)
    return math.hypot(horizontal, vertical)


def held_in_tcp(grasp_position: Sequence[float], grasp_rotation: Sequence[Sequence[float]],
                object_position: Sequence[float], closing_axis: Sequence[float]) -> np.ndarray:
    """The centre (m, tcp frame) of an object that stood at ``object_position`` when the tcp took
    it at ``grasp_position`` with ``grasp_rotation`` (3x3; all one frame), centred between the
    fingers: closing fingers push it to their middle, so its offset along ``closing_axis`` (tcp
    frame) is 0. The detector's tracker and the environment's model of it both hold an object so.
    """
    offset = np.asarray(grasp_rotation, dtype=np.float64).T @ (
        np.asarray(object_position[:3], dtype=np.float64) - np.asarray(grasp_position, dtype=np.float64))
    axis = np.asarray(closing_axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return offset - float(offset @ axis) * axis


def quaternion_of_yaw(yaw: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a frame turned ``yaw`` (rad) about the parent's z axis: upright at that yaw."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def yaw_of(quaternion: Sequence[float]) -> float:
    """Yaw (rad) of a frame's x axis in the parent's xy plane, from its quaternion (x, y, z, w)."""
    x, y, z, w = quaternion
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))
