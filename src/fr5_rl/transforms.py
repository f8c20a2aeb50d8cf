"""Rigid transforms as 4x4 matrices, and the static transform table in config/ (no ROS needed)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .config import DEFAULT_ROBOT, ConfigError, config_path, load_typed
from .kinematics import rotation_from_rpy


@dataclass(frozen=True)
class StaticTransform:
    """One fixed frame: ``child`` in ``parent``, xyz (m) and URDF roll-pitch-yaw (rad)."""

    parent: str
    child: str
    xyz: List[float]
    rpy: List[float]


@dataclass(frozen=True)
class StaticTransforms:
    """``config/static_transforms.yaml``: every transform published on /tf_static.

    ``simulator_default`` marks the shipped file, whose camera mount is the simulator's: a real
    cell must measure its own (``calibrate_camera.py`` writes a file without the mark), and
    ``real_policy.launch`` warns loudly while the mark is there.
    """

    transforms: List[StaticTransform]
    simulator_default: bool = False

    def check(self, source: str) -> None:
        for index, item in enumerate(self.transforms):
            if len(item.xyz) != 3 or len(item.rpy) != 3 or not np.all(np.isfinite(item.xyz + item.rpy)):
                raise ConfigError(f"{source}: 'transforms[{index}]' ({item.parent} -> {item.child}): "
                                  "xyz and rpy need 3 finite values each")
        children = [item.child for item in self.transforms]
        if len(set(children)) != len(children):
            raise ConfigError(f"{source}: a child frame appears twice (tf allows one parent per frame)")



def matrix_from_xyz_rpy(xyz, rpy) -> np.ndarray:
    """4x4 homogeneous transform from a translation (m) and URDF roll-pitch-yaw (rad)."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotation_from_rpy(*rpy)
    matrix[:3, 3] = xyz
    return matrix


def quaternion_from_matrix(rotation: np.ndarray) -> Tuple[float, float, float, float]:
    """3x3 rotation -> unit quaternion (x, y, z, w)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    return tuple(float(v) for v in q)


def quaternion_z_axis(quaternion: Sequence[float]) -> Tuple[float, float, float]:
    """The z axis (third rotation column) of a quaternion (x, y, z, w), as plain floats.

    Normalised as PyBullet's ``getMatrixFromQuaternion`` does: simulator quaternions are unit
    length only to ~1e-7, and near vertical ``acos`` of the axis magnifies that.
    """
    x, y, z, w = quaternion
    s = 2.0 / (x * x + y * y + z * z + w * w)
    return s * (x * z + y * w), s * (y * z - x * w), 1.0 - s * (x * x + y * y)


def matrix_from_quaternion(xyz, quaternion) -> np.ndarray:
    """4x4 transform from a translation (m) and a quaternion (x, y, z, w)."""
    x, y, z, w = quaternion
    matrix = np.eye(4)
    matrix[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    matrix[:3, 3] = xyz
    return matrix


SHIPPED_TRANSFORMS = "static_transforms"  # the shipped cell's file: the FR5's, or each arm's own


def transforms_of_arm(path: str | Path, robot: Optional[str]) -> str | Path:
    """``path``, unless it is the shipped cell's file (``static_transforms``, by name or as
    ``config/static_transforms.yaml``) and ``robot`` is another arm than the FR5: then that arm's
    cell, ``static_transforms_<robot>`` (its camera in front of its own placement region, its
    table), which the FR5's would miss. A file of one's own (a calibration) is kept as it is, and
    so is any file for a name that is not one of the family's (a vendor's URDF's, say)."""
    from .config import robot_names

    if robot in (None, DEFAULT_ROBOT) or robot not in robot_names():
        return path
    shipped = str(path) == SHIPPED_TRANSFORMS or (
        str(path).endswith(".yaml") and Path(path).resolve() == config_path(SHIPPED_TRANSFORMS).resolve())
    return f"{SHIPPED_TRANSFORMS}_{robot}" if shipped else path


def load_static_transforms(path: str | Path = SHIPPED_TRANSFORMS, robot: Optional[str] = None) -> List[Dict]:
    """Entries of ``config/static_transforms.yaml`` (or ``path``: a path, or a name in ``config/``,
    e.g. ``camera_frames``), checked by :class:`StaticTransforms`: dicts with parent, child,
    xyz (m), rpy (rad), matrix (4x4).

    :param robot: the arm on the cell: the shipped file stands for its own (:func:`transforms_of_arm`).
    """
    table = load_typed(StaticTransforms, transforms_of_arm(path, robot))
    return [{"parent": item.parent, "child": item.child, "xyz": item.xyz, "rpy": item.rpy,
             "matrix": matrix_from_xyz_rpy(item.xyz, item.rpy)} for item in table.transforms]


def load_transform_files(paths: Sequence[str | Path], robot: Optional[str] = None) -> List[Dict]:
    """The entries of several transform files (paths, or names in ``config/``), in order, as one
    table, as :func:`load_static_transforms` gives them plus ``source`` (the path or name it
    came from, as given). A child frame listed in two files is
    refused: tf allows one parent per frame (e.g. a mount file that still holds the camera's
    optical frame, which the camera driver publishes).

    :param paths: the files, e.g. ``["static_transforms", "camera_frames"]``.
    :param robot: the arm on the cell: the shipped file stands for its own (:func:`transforms_of_arm`).
    :raises ConfigError: a file is missing or wrong, or two files set the same child frame.
    """
    entries: List[Dict] = []
    owner: Dict[str, str] = {}
    for path in paths:
        for entry in load_static_transforms(path, robot):
            if entry["child"] in owner:
                raise ConfigError(f"{entry['child']} has a parent in both {owner[entry['child']]} and {path}: "
                                  "tf allows one parent per frame")
            owner[entry["child"]] = str(path)
            entries.append({**entry, "source": str(path)})
    return entries


def transform_in(entries: List[Dict], parent: str, child: str) -> np.ndarray:
    """The configured transform parent <- child (4x4), chained up the tree from ``child``
    (e.g. base_link <- camera_link <- camera_color_optical_frame), or ConfigError if the
    entries do not connect them."""
    by_child = {entry["child"]: entry for entry in entries}
    matrix, frame, hops = np.eye(4), child, 0
    while frame != parent:
        entry = by_child.get(frame)
        hops += 1
        if entry is None or hops > len(entries):  # not listed, or a loop of entries that never reaches parent
            raise ConfigError(f"the static transforms (config/static_transforms.yaml, and config/camera_frames.yaml "
                              f"where given) do not connect {child} to {parent}")
        matrix = entry["matrix"] @ matrix
        frame = entry["parent"]
    return matrix
