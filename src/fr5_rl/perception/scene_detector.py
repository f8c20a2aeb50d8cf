"""Every object on the table in one frame (issue #54), or why a piece is none.

:class:`~fr5_rl.perception.detector.ObjectDetector` finds *the* object and refuses a frame with
several. :func:`detect_scene` reports each one instead, with its kind (cylinder, square box,
rectangular box), and refuses the pieces it cannot take for one whole object, with the reason:

- hidden by or touching the robot (``OCCLUDED``);
- half out of the camera's view (``PARTIAL``: at the image's border);
- objects it cannot tell apart (``TOUCHING``): a top face wider than any object, a piece with two
  top levels, or a top face that is not convex (two footprints joined);
- too small to be an object.

Two objects of one height set face to face can make a top face one object could have (two 3 cm
cubes are a 6 x 3 cm box to a depth camera); nothing in a depth image tells those apart.

Pure numpy, like the detector it builds on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np

from .camera_model import Intrinsics
from ..config import ConfigError
from .detector import Detection, ObjectDetector, Pieces, RefusalReason, load_section

#: A second top level must cover this much of its outline (cells counted), so that a side's band
#: of points is no top.
LEVEL_CONVEXITY = 0.7
#: m, the height bins a second level is looked for in (it takes its bin and the two beside it).
LEVEL_BIN = 0.004
#: m, the cells a second level's points are counted in: coarser than a pixel's footprint, so that
#: a top seen at a slant has no holes.
LEVEL_CELL = 0.005
#: m, the cells the top face's points are counted in for its area (about a pixel's footprint at
#: the shipped mount's range, so that the face has no holes).
FACE_CELL = 0.003


@dataclass(frozen=True)
class SceneDetectorSettings:
    """The ``scene`` section of ``config/detector.yaml``: how pieces are cut apart and told from
    several objects touching (:func:`detect_scene`).

    :param depth_jump: m: neighbouring pixels further apart in depth are two things, one in front
        of the other.
    :param side_tolerance: m added to the widest object's side for the measurement's error.
    :param min_convexity: a top face covering less of its convex hull than this is two
        footprints joined.
    :param level_gap: m: a second flat level this far below the top face is a second object's top.
    """

    depth_jump: float
    side_tolerance: float
    min_convexity: float
    level_gap: float

    def check(self, source: str) -> None:
        """Refuse thresholds that would cut or refuse everything (called by :func:`fr5_rl.config.typed`)."""
        if not (self.depth_jump > 0 and self.side_tolerance >= 0 and 0 < self.min_convexity <= 1
                and self.level_gap > 0):
            raise ConfigError(f"{source}: needs depth_jump > 0, side_tolerance >= 0, 0 < min_convexity <= 1 "
                              "and level_gap > 0")

    @classmethod
    def from_yaml(cls, path_or_name: Union[str, Path] = "detector") -> "SceneDetectorSettings":
        """The ``scene`` section of ``config/detector.yaml`` (or of another file), checked."""
        return load_section(cls, "scene", path_or_name)


@dataclass(frozen=True)
class SceneLimits:
    """What one object can look like: the objects a cell handles and the detector's thresholds.

    :param max_side: m, the longest top side (or diameter) of any object; a wider top face is
        several objects.
    :param min_top: m^2, the smallest top face of any object.
    :param square_difference: m: a box whose measured top sides differ by less than this is square.
    :param settings: the thresholds (:class:`SceneDetectorSettings`).
    """

    max_side: float
    min_top: float
    square_difference: float
    settings: SceneDetectorSettings

    @classmethod
    def from_objects(cls, variety, rectangular_min_difference: float,
                     settings: Optional[SceneDetectorSettings] = None) -> "SceneLimits":
        """The limits of ``object.variety`` (:class:`fr5_rl.env_config` ``VarietyConfig``): the
        longest side of its boxes or diameter of its cylinders, the smallest top; square below half
        the difference an oblong box's sides keep (``config/scenes.yaml`` ``rectangular_min_difference``).

        :param settings: the thresholds; None: ``config/detector.yaml``'s.
        """
        longest = max(float(variety.box_side[1]), 2.0 * float(variety.cylinder_radius[1]))
        smallest = min(float(variety.box_side[0]) ** 2, math.pi * float(variety.cylinder_radius[0]) ** 2)
        return cls(longest, smallest, 0.5 * rectangular_min_difference,
                   settings if settings is not None else SceneDetectorSettings.from_yaml())


@dataclass(frozen=True)
class SceneObjectFound:
    """One object the frame shows whole.

    :param detection: its measurement (centre, top height, kind, yaw, extents).
    :param label: ``cylinder``, ``square box`` or ``rectangular box``.
    """

    detection: Detection
    label: str


@dataclass(frozen=True)
class RefusedPiece:
    """A piece that is not one whole object.

    :param reason: ``OCCLUDED``, ``PARTIAL``, ``TOUCHING`` or ``NO_OBJECT`` (too small).
    :param detail: what exactly.
    :param position_table: its centre on the table (m, table frame: x, y, top height).
    """

    reason: RefusalReason
    detail: str
    position_table: Tuple[float, float, float]


@dataclass(frozen=True)
class SceneDetection:
    """Every object found in a frame, and every piece refused."""

    objects: Tuple[SceneObjectFound, ...]
    refused: Tuple[RefusedPiece, ...]


def detect_scene(detector: ObjectDetector, limits: SceneLimits, depth: np.ndarray, intrinsics: Intrinsics,
                 table_from_optical: np.ndarray) -> SceneDetection:
    """Each object standing on the table in the region, and each piece that is not one.

    :param detector: the single-object detector whose segmentation and measurement are used.
    :param limits: what one object can look like.
    :param depth: (H, W) metres along the optical axis, 0 = no data.
    :param intrinsics: the image's camera model.
    :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame.
    """
    pieces = detector.segment(depth, intrinsics, table_from_optical, depth_jump=limits.settings.depth_jump)
    found, refused = [], []
    for index in pieces.occluded:
        refused.append(RefusedPiece(RefusalReason.OCCLUDED, "hidden by or touching the robot", _centre(pieces, index)))
    for index in pieces.behind:
        refused.append(RefusedPiece(RefusalReason.OCCLUDED, "behind another object in the camera's view",
                                    _centre(pieces, index)))
    for detail, index in pieces.at_border:
        refused.append(RefusedPiece(RefusalReason.PARTIAL, f"half out of view: {detail}", _centre(pieces, index)))
    for detail, index in pieces.rejected:
        if float(pieces.footprint.ravel()[index].sum()) > detector.settings.max_area:
            refused.append(RefusedPiece(RefusalReason.TOUCHING, f"{detail}: larger than any one object",
                                        _centre(pieces, index)))
        else:
            refused.append(RefusedPiece(RefusalReason.NO_OBJECT, f"{detail}: too small to be an object",
                                        _centre(pieces, index)))
    for index in pieces.candidates:
        detection = detector.measure(pieces, index)
        why = _several(pieces, index, detection, limits, detector.settings.top_tolerance,
                       detector.table.table_height)
        if why is not None:
            refused.append(RefusedPiece(RefusalReason.TOUCHING, why,
                                        (*detection.position_table[:2], detection.top_height)))
            continue
        found.append(SceneObjectFound(detection, label_of(detection, limits)))
    return SceneDetection(tuple(found), tuple(refused))


def label_of(detection: Detection, limits: SceneLimits) -> str:
    """``cylinder``, ``square box`` or ``rectangular box``, from the measured top face."""
    if detection.kind == "cylinder":
        return "cylinder"
    longer, shorter = detection.extents
    return "square box" if longer - shorter < limits.square_difference else "rectangular box"


def _several(pieces: Pieces, index: np.ndarray, detection: Detection, limits: SceneLimits,
             top_tolerance: float, table_height: float) -> Optional[str]:
    """Why the piece is more than one object, or None."""
    settings = limits.settings
    widest = max(detection.extents)
    if widest > limits.max_side + settings.side_tolerance:
        return (f"a top face {widest * 100:.1f} cm across, wider than any object "
                f"({limits.max_side * 100:.1f} cm): objects touching")
    heights = pieces.height.ravel()[index]
    x, y = pieces.px.ravel()[index], pieces.py.ravel()[index]
    top = heights >= np.percentile(heights, 90) - top_tolerance
    convexity = _convexity(x[top], y[top], _horizontal_areas(pieces, index[top], table_height))
    if convexity < settings.min_convexity:
        return f"a top face covering {convexity:.0%} of its outline: two footprints joined"
    # A second flat level well below the top face: another object's top (an object's own sides
    # are vertical, so their points spread over many heights and cover no area at any one).
    below = heights < detection.top_height - settings.level_gap
    if below.sum() > 0:
        bins = np.round(heights[below] / LEVEL_BIN)
        values, counts = np.unique(bins, return_counts=True)
        level = values[np.argmax(counts)]
        on_level = below.copy()
        on_level[below] = np.abs(bins - level) <= 1
        area = _face_area(x[on_level], y[on_level])
        # Most of the smallest top, and whole: an object's side seen at a slant leaves a
        # thin band of points at each height, spread further by depth noise.
        if area >= 0.75 * limits.min_top and _convexity(x[on_level], y[on_level], cell=LEVEL_CELL) >= LEVEL_CONVEXITY:
            return (f"a second top {area * 1e4:.0f} cm^2 at {level * LEVEL_BIN * 100:.1f} cm, below this one at "
                    f"{detection.top_height * 100:.1f} cm: objects touching")
    return None


def _centre(pieces: Pieces, index: np.ndarray) -> Tuple[float, float, float]:
    """A piece's mean position on the table and its highest point (m)."""
    return (float(pieces.px.ravel()[index].mean()), float(pieces.py.ravel()[index].mean()),
            float(pieces.height.ravel()[index].max()))


def _cells(x: np.ndarray, y: np.ndarray, cell: float = FACE_CELL) -> np.ndarray:
    """The cells ``cell`` m wide (their indices, unique) that points fall in."""
    return np.unique(np.stack([np.floor(x / cell), np.floor(y / cell)], axis=1), axis=0)


def _face_area(x: np.ndarray, y: np.ndarray, cell: float = FACE_CELL) -> float:
    """m^2 the points cover on the table, counted in cells ``cell`` m wide."""
    return float(len(_cells(x, y, cell))) * cell ** 2 if x.size else 0.0


def _horizontal_areas(pieces: Pieces, index: np.ndarray, table_height: float) -> np.ndarray:
    """m^2 each pixel of a piece covers on a horizontal plane through it: its footprint seen
    square-on, times cos(ray to optical axis) / cos(ray to vertical)."""
    pose = np.asarray(pieces.table_from_optical, dtype=np.float64)
    origin, optical_axis = pose[:3, 3], pose[:3, 2]
    dx = pieces.px.ravel()[index] - origin[0]
    dy = pieces.py.ravel()[index] - origin[1]
    dz = pieces.height.ravel()[index] + table_height - origin[2]
    along = dx * optical_axis[0] + dy * optical_axis[1] + dz * optical_axis[2]
    return pieces.footprint.ravel()[index] * along / np.maximum(np.abs(dz), 1e-6)


def _convexity(x: np.ndarray, y: np.ndarray, areas: Optional[np.ndarray] = None, cell: float = FACE_CELL) -> float:
    """The share of its convex hull that a face covers (1 for a convex face): its points
    (x, y, m) and the area each covers (m^2; None: counted in cells ``cell`` m wide)."""
    if x.size < 3:
        return 1.0
    area = _face_area(x, y, cell) if areas is None else float(areas.sum())
    pixel = cell if areas is None else math.sqrt(float(areas.mean()))
    # The hull's corners are among each band's outermost points (bands a cell wide, both ways).
    extremes = []
    for along, across in ((x, y), (y, x)):
        band = np.floor(across / FACE_CELL)
        order = np.lexsort((along, band))
        first = np.r_[True, band[order][1:] != band[order][:-1]]
        last = np.r_[band[order][1:] != band[order][:-1], True]
        extremes.append(order[first | last])
    keep = np.unique(np.concatenate(extremes))
    points = np.unique(np.stack([x[keep], y[keep]], axis=1), axis=0)
    corners = _hull(points)
    if len(corners) < 3:
        return 1.0
    cx, cy = corners[:, 0], corners[:, 1]
    hull = 0.5 * abs(float(np.dot(cx, np.roll(cy, -1)) - np.dot(cy, np.roll(cx, -1))))
    perimeter = float(np.sum(np.hypot(*(np.roll(corners, -1, axis=0) - corners).T)))
    # The hull runs through the outer points' centres: half a pixel around it is the face's too.
    return min(1.0, area / (hull + 0.5 * pixel * perimeter + pixel * pixel))


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull's corners of unique, sorted points (Andrew's monotone chain), counter-clockwise."""
    if len(points) < 3:
        return points

    def half(sequence: np.ndarray) -> list:
        chain: list = []
        for point in sequence:
            while len(chain) >= 2 and _cross(chain[-2], chain[-1], point) <= 0.0:
                chain.pop()
            chain.append(point)
        return chain

    lower, upper = half(points), half(points[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

