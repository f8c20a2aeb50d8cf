"""Finding the one object that stands on the table in an aligned RGB-D frame (pure numpy: no
ROS, no pybullet; the detector node is I/O around it).

The detector does not know the object's colour. It measures, for every pixel with depth, the
height above the calibrated table plane, keeps what stands between ``min_height`` and
``max_object_height`` inside the placement region (with a margin), splits that into connected
pieces, and throws away the pieces that are the robot:

- anything higher than ``max_object_height`` is the robot (the arm and the gripper body);
  a piece that touches it (within ``robot_margin_px``) is hidden under or held by the gripper,
  so its visible part would give a biased centre: it is not used (``OCCLUDED``);
- a piece that touches the image border is only partly in view; one whose area (on the
  table) is not that of a graspable object is not it.

Exactly one piece left is the object. Its top face (the points within ``top_tolerance`` of the
piece's top height) gives the centre in x, y; the centre's height is the top minus half the
object's height (``object_height``, or, when 0, half the top's height above the table: a
resting object). That is the point the simulator reports as the object's pose.

Every frame either gives a :class:`Detection` or a :class:`Refusal` whose
:class:`RefusalReason` says why nothing is published.

The thresholds are the ``detector`` section of ``config/detector.yaml`` (:class:`DetectorSettings`,
no defaults in code); the table and the placement region are ``config/env.yaml``'s
(:class:`TableRegion`).
"""
from __future__ import annotations

import cmath
import dataclasses
import enum
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, List, Optional, Tuple, Type, TypeVar, Union

import numpy as np

from ..config import ConfigError, load_yaml, typed
from ..objects import ObjectShape
from .camera_model import Intrinsics
from .morphology import dilate, label_components

T = TypeVar("T")


def load_section(cls: Type[T], section: str, path_or_name: Union[str, Path] = "detector") -> T:
    """``section`` of a YAML file (a path, or a name in ``config/``) as the dataclass ``cls``
    (:func:`fr5_rl.config.typed`: unknown, missing and mistyped keys refused, then checked).

    :param section: the top-level key, e.g. ``detector`` or ``tracker``.
    """
    path = Path(path_or_name)
    source = str(path) if path.is_file() else f"config/{path_or_name}.yaml"
    return typed(cls, load_yaml(path_or_name).get(section), source, section)

class RefusalReason(enum.Enum):
    """Why a frame gives no detection (the node holds: publishes nothing, warns)."""

    CAMERA_INFO = "camera_info missing or unusable"
    ENCODING = "unsupported image encoding"
    SIZE_MISMATCH = "colour, depth and camera_info sizes differ"
    BAD_IMAGE = "image data does not match its size"
    DEPTH_INVALID = "depth holds no usable data"
    STALE = "images older than the timeout"
    NO_TRANSFORM = "no transform from the table frame to the camera"
    NO_OBJECT = "no object on the table"
    SEVERAL_OBJECTS = "more than one object candidate"
    OCCLUDED = "object hidden by or touching the robot"
    PARTIAL = "object half out of the camera's view"
    TOUCHING = "objects touching: not told apart"


@dataclass(frozen=True)
class Refusal:
    """No detection this frame.

    :param reason: the kind of problem.
    :param detail: what exactly, for the warning.
    :param candidates: with ``SEVERAL_OBJECTS``, each candidate measured as if it were the
        object, so a tracker that knows the object can tell it from pieces of the robot.
    """

    reason: RefusalReason
    detail: str = ""
    candidates: Tuple["Detection", ...] = ()

    def __str__(self) -> str:
        return f"{self.reason.value}" + (f": {self.detail}" if self.detail else "")


# How far a face is from a disc, from its moments about the centre, z = dx + i dy (table frame):
# max(|E[z^2]| / E[|z|^2], |E[z^4]| / E[|z|^2]^2). A disc's is 0 (both moments vanish); a square's
# 0.6; a rectangle's at least ~0.33 (sides 1.42 : 1; more oblong, the second moment grows). A box's
# top above this. Moments average over the whole face, where the farthest point (the former test)
# is one pixel: with a D435's depth noise (2 mm at 1 m) the top face's rim is ragged, and 8 of 20
# cylinders on the oblique view were called boxes.
BOX_NON_ROUNDNESS = 0.15
# A face's second-moment anisotropy, (major - minor) / (major + minor): (a^2 - b^2) / (a^2 + b^2)
# for a rectangle of sides a >= b. Below this (a / b < ~1.36) its sides' direction comes from the
# fourth moment instead: a square's second moments are alike in every direction, so their axes
# are pixel noise (on the oblique RealSense view, square tops' yaw was 7 deg off at the median,
# 21 deg at worst).
SECOND_MOMENT_ANISOTROPY = 0.3


def face_shape(dx: np.ndarray, dy: np.ndarray, weights: np.ndarray) -> Tuple[str, float, Tuple[float, float]]:
    """A top face's kind, yaw and extents from its points about their centre.

    :param dx: the points' x (m, table frame) minus the centre's.
    :param dy: their y likewise.
    :param weights: each point's share of the face's area (summing to 1).
    :return: ``(kind, yaw, (longer, shorter))``: see :class:`Detection`; a box's yaw in
        (-pi / 2, pi / 2] (rad, table frame).
    """
    z = dx + 1j * dy
    squared = z * z
    spread = float(weights @ (dx * dx + dy * dy))
    # Over a rectangle turned by yaw: E[z^2] = e^(2i yaw) (var_along - var_across), and
    # E[z^4] = -c e^(4i yaw) with c > 0 while a / b < sqrt(3) (its corners, at yaw + 45 deg, lie
    # farthest out): the sides' direction modulo 90 deg.
    second = complex(weights @ squared)
    fourth = complex(weights @ (squared * squared))
    if spread <= 0.0 or max(abs(second) / spread, abs(fourth) / spread ** 2) < BOX_NON_ROUNDNESS:
        # A disc's radial variance is r^2 / 2.
        diameter = 2.0 * math.sqrt(2.0 * max(spread, 0.0))
        return "cylinder", 0.0, (diameter, diameter)
    if abs(second) >= SECOND_MOMENT_ANISOTROPY * spread:
        yaw = 0.5 * cmath.phase(second)
    else:
        yaw = 0.25 * cmath.phase(-fourth)
    along = dx * math.cos(yaw) + dy * math.sin(yaw)
    across = dy * math.cos(yaw) - dx * math.sin(yaw)
    # A uniform rectangle's variance along a side of length L is L^2 / 12.
    longer, shorter = float(weights @ (along * along)), float(weights @ (across * across))
    if shorter > longer:  # the fourth moment gave the shorter side: x is the other one
        longer, shorter, yaw = shorter, longer, yaw + 0.5 * math.pi
    yaw = math.pi / 2.0 - (math.pi / 2.0 - yaw) % math.pi  # in (-pi / 2, pi / 2]
    return "box", yaw, (math.sqrt(12.0 * longer), math.sqrt(12.0 * max(shorter, 0.0)))


@dataclass(frozen=True)
class Detection:
    """The object found in one frame.

    :param position: object centre (m) in the optical frame of the image.
    :param position_table: the same point in the table frame (m).
    :param top_height: height (m) of the object's top face above the table.
    :param pixel: (u, v) of the top face's centre in the image (pixels).
    :param radius_px: rough radius (pixels) of the object's image, for drawing.
    :param pixels: pixels the object covers.
    :param size: the top face's width (m) in the table plane (its equivalent diameter): what the
        fingers close to when they hold it.
    :param kind: ``box`` or ``cylinder``, from the top face's shape (a disc's second and fourth
        moments vanish, a rectangle's do not: :func:`face_shape`).
    :param yaw: rad, in the table frame: a box's longer top side (its own x; modulo pi, modulo
        pi / 2 for a square top); 0 for a cylinder.
    :param extents: (longer, shorter) side of a box's top, or a cylinder's diameter twice (m).
    """

    position: Tuple[float, float, float]
    position_table: Tuple[float, float, float]
    top_height: float
    pixel: Tuple[float, float]
    radius_px: float
    pixels: int
    size: float = 0.0
    kind: str = "cylinder"
    yaw: float = 0.0
    extents: Tuple[float, float] = (0.0, 0.0)

    @property
    def shape(self) -> Optional[ObjectShape]:
        """The object's shape if it stands on the table: extents (m) along its own x, y, z, a
        box's longer and shorter top sides (x along :attr:`yaw`), a cylinder's diameter twice, and
        its top's height; None where the sides were not measured (zero)."""
        if min(*self.extents, self.top_height) <= 0.0:
            return None
        return ObjectShape(self.kind, (float(self.extents[0]), float(self.extents[1]), float(self.top_height)))


@dataclass(frozen=True)
class DetectorSettings:
    """What the detector looks for: the ``detector`` section of ``config/detector.yaml``, where
    every default lives (:meth:`from_yaml`).

    :param region_margin: m added around the placement region (an object pushed slightly out
        still counts).
    :param min_height: m above the table below which a point is table (depth noise, tilt).
    :param max_object_height: m above the table above which a point is the robot.
    :param top_tolerance: m below the top height that still counts as the top face.
    :param object_height: the object's height (m) when known; 0: estimated from its top
        (valid for an object standing on the table).
    :param min_area: smallest object footprint seen from the camera (m^2).
    :param max_area: largest (m^2).
    :param robot_margin_px: a piece within this many pixels of the robot is occluded.
    :param min_valid_depth_fraction: a frame with less valid depth than this is refused
        (:func:`fr5_rl.perception.images.check_frame`).
    """

    region_margin: float
    min_height: float
    max_object_height: float
    top_tolerance: float
    object_height: float
    min_area: float
    max_area: float
    robot_margin_px: int
    min_valid_depth_fraction: float

    def check(self, source: str) -> None:
        """Refuse thresholds that leave nothing to detect (called by :func:`fr5_rl.config.typed`)."""
        if not 0 <= self.min_height < self.max_object_height or not 0 < self.min_area < self.max_area:
            raise ConfigError(f"{source}: needs 0 <= min_height < max_object_height and 0 < min_area < max_area")

    @classmethod
    def from_yaml(cls, path_or_name: Union[str, Path] = "detector") -> "DetectorSettings":
        """The ``detector`` section of ``config/detector.yaml`` (or of another file: a path, or
        a name in ``config/``), checked."""
        return load_section(cls, "detector", path_or_name)


@dataclass(frozen=True)
class TableRegion:
    """Where objects are placed: the table plane and the placement region on it
    (``config/env.yaml``: ``table.top_height``, ``object.region_low`` and ``region_high``).

    :param region_low: (x, y) low corner (m) of the placement region in the table frame.
    :param region_high: (x, y) high corner (m).
    :param table_height: z (m) of the table top in the table frame.
    """

    region_low: Tuple[float, float]
    region_high: Tuple[float, float]
    table_height: float

    @classmethod
    def from_env(cls, env: Any) -> "TableRegion":
        """The region of an env configuration (:class:`fr5_rl.env_config.EnvConfig`, as
        :func:`fr5_rl.env_config.load_env_config` gives it)."""
        return cls(tuple(float(v) for v in env.object.region_low), tuple(float(v) for v in env.object.region_high),
                   float(env.table.top_height))


@dataclass
class Pieces:
    """What stands on the table in the region of one frame, split into connected pieces
    (:meth:`ObjectDetector.segment`); each piece is the flat indices of its pixels in the region
    window. The arrays are the window's, per pixel: height above the table (m), table-frame x and
    y (m), footprint seen square-on (m^2).

    :param count: pieces found, of every kind.
    :param candidates: pieces that may be one object each.
    :param occluded: pieces the robot hides or touches.
    :param rejected: ``(why, piece)``: too small or too large.
    :param at_border: ``(why, piece)``: touching the image's border (partly in view).
    :param behind: pieces another piece stands in front of in the camera's view (only when
        segmented with a ``depth_jump``): part of their top may be hidden.
    """

    count: int
    candidates: List[np.ndarray]
    occluded: List[np.ndarray]
    rejected: List[Tuple[str, np.ndarray]]
    height: np.ndarray
    px: np.ndarray
    py: np.ndarray
    footprint: np.ndarray
    table_from_optical: np.ndarray
    intrinsics: Intrinsics
    width: int
    behind: List[np.ndarray] = dataclasses.field(default_factory=list)
    at_border: List[Tuple[str, np.ndarray]] = dataclasses.field(default_factory=list)


#: The eight neighbours of a pixel, (row, column) shifts: pieces are 8-connected
#: (:func:`~fr5_rl.perception.morphology.label_components`), so a cut must be too.
NEIGHBOURS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))


def _shifted(a: np.ndarray, dr: int, dc: int, fill) -> np.ndarray:
    """``a`` moved by (dr, dc): entry (r, c) of the result is ``a[r + dr, c + dc]`` (``fill`` outside)."""
    out = np.full_like(a, fill)
    h, w = a.shape
    out[max(-dr, 0):h - max(dr, 0), max(-dc, 0):w - max(dc, 0)] = a[max(dr, 0):h - max(-dr, 0),
                                                                    max(dc, 0):w - max(-dc, 0)]
    return out


def _far_side_of_jumps(z: np.ndarray, standing: np.ndarray, jump: float) -> np.ndarray:
    """Standing pixels with a standing neighbour nearer to the camera by more than ``jump`` (m):
    the rim of whatever stands behind something else in the view."""
    far = np.zeros_like(standing)
    for dr, dc in NEIGHBOURS:
        neighbour_z = _shifted(z, dr, dc, 0.0)
        neighbour_standing = _shifted(standing, dr, dc, False)
        far |= standing & neighbour_standing & (z - neighbour_z > jump)
    return far


def _labels_behind(labels: np.ndarray, z: np.ndarray, far: np.ndarray, jump: float) -> set:
    """The labels of the pieces that stand behind another one: the rim pixels ``far`` next to a
    labelled neighbour at about their depth (within ``jump``, m; the piece behind) and to one
    nearer by more than ``jump`` of another piece (in front). A rim between two parts of one
    piece (its own surface seen at a grazing angle) puts nothing behind."""
    rim_label = np.zeros_like(labels)  # the piece a rim pixel belongs to
    front_label = np.zeros_like(labels)  # a piece in front of it
    for dr, dc in NEIGHBOURS:
        neighbour_label = _shifted(labels, dr, dc, 0)
        neighbour_z = _shifted(z, dr, dc, 0.0)
        labelled = far & (neighbour_label > 0)
        same = labelled & (np.abs(z - neighbour_z) <= jump)
        rim_label[same] = neighbour_label[same]
        nearer = labelled & (z - neighbour_z > jump)
        front_label[nearer] = neighbour_label[nearer]
    pairs = (rim_label > 0) & (front_label > 0) & (rim_label != front_label)
    return {int(label) for label in np.unique(rim_label[pairs])}


class ObjectDetector:
    """The object in a frame, given the camera model and the camera's pose over the table.

    :param settings: the thresholds (:class:`DetectorSettings`).
    :param table: the table plane and the placement region (:class:`TableRegion`).
    """

    def __init__(self, settings: DetectorSettings, table: TableRegion) -> None:
        self.settings = settings
        self.table = table
        # Caches: the rays of the last camera model, the region window of the last camera pose.
        self._rays: Optional[Tuple[Intrinsics, np.ndarray, np.ndarray]] = None
        self._window: Optional[Tuple[Tuple[Intrinsics, bytes], Tuple[int, int, int, int]]] = None

    def _ray_grid(self, intrinsics: Intrinsics) -> Tuple[np.ndarray, np.ndarray]:
        if self._rays is None or self._rays[0] != intrinsics:
            u = np.arange(intrinsics.width, dtype=np.float32)
            v = np.arange(intrinsics.height, dtype=np.float32)
            x, y = intrinsics.ray(u, v)
            self._rays = (intrinsics, x.astype(np.float32), y.astype(np.float32))
        return self._rays[1], self._rays[2]

    def region_window(self, intrinsics: Intrinsics, table_from_optical: np.ndarray) -> Tuple[int, int, int, int]:
        """``(top, bottom, left, right)`` (pixels, end exclusive) of the image part that can show
        the placement region (with its margin) from the table up to ``max_object_height``, plus
        the robot margin; the whole image when part of that box lies behind the camera."""
        s, t = self.settings, self.table
        key = (intrinsics, np.asarray(table_from_optical, dtype=np.float64).tobytes())
        if self._window is not None and self._window[0] == key:
            return self._window[1]
        m = s.region_margin
        corners = np.array([[x, y, t.table_height + h, 1.0]
                            for x in (t.region_low[0] - m, t.region_high[0] + m)
                            for y in (t.region_low[1] - m, t.region_high[1] + m)
                            for h in (0.0, s.max_object_height)]).T
        optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ corners
        window = (0, intrinsics.height, 0, intrinsics.width)
        if (optical[2] > 1e-3).all():
            pixels = intrinsics.project(optical[:3].T)
            pad = max(s.robot_margin_px, 1) + 2
            window = (int(np.clip(np.floor(pixels[:, 1].min()) - pad, 0, intrinsics.height)),
                      int(np.clip(np.ceil(pixels[:, 1].max()) + pad + 1, 0, intrinsics.height)),
                      int(np.clip(np.floor(pixels[:, 0].min()) - pad, 0, intrinsics.width)),
                      int(np.clip(np.ceil(pixels[:, 0].max()) + pad + 1, 0, intrinsics.width)))
        self._window = (key, window)
        return window

    def detect(self, depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
               color: Optional[np.ndarray] = None) -> Union[Detection, Refusal]:
        """Find the object.

        :param depth: (H, W) float metres along the optical axis, 0 = no data.
        :param intrinsics: the camera model of the image.
        :param table_from_optical: 4x4 pose (m) of the image's optical frame in the table frame
            (z up, the table top at ``table.table_height``).
        :param color: (H, W, 3) uint8, unused by the geometry (kept for optional colour filters).
        :return: the :class:`Detection`, or the :class:`Refusal` saying why there is none.
        """
        pieces = self.segment(depth, intrinsics, table_from_optical)
        if pieces.count == 0:
            return Refusal(RefusalReason.NO_OBJECT, "nothing stands on the table in the region")
        if not pieces.candidates:
            if pieces.occluded:
                return Refusal(RefusalReason.OCCLUDED, f"{len(pieces.occluded)} piece(s) next to the robot")
            rejected = [detail for detail, _ in pieces.at_border + pieces.rejected]
            return Refusal(RefusalReason.NO_OBJECT, "pieces rejected: " + ", ".join(rejected) if rejected
                           else "only pieces too small to be the object")
        found = [self.measure(pieces, index) for index in pieces.candidates]
        if len(found) > 1:
            return Refusal(RefusalReason.SEVERAL_OBJECTS, f"{len(found)} candidates", tuple(found))
        return found[0]

    def segment(self, depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
                depth_jump: Optional[float] = None) -> "Pieces":
        """The pieces standing on the table in the region, sorted: candidates, pieces the robot
        hides or touches, and pieces rejected (at the image's border, too small or too large).

        :param depth: as for :meth:`detect`.
        :param depth_jump: m; None: pixels next to each other in the image are one piece
            whatever their depths (one object). Given: neighbours further apart in depth than this
            are cut apart, so that an object standing in front of another in the camera's view
            is a piece of its own, and the one behind it goes to ``Pieces.behind``.
        """
        s, t = self.settings, self.table
        rx, ry = self._ray_grid(intrinsics)
        # Only the part of the image where the placement region can show: all the rest is
        # neither object nor robot next to one (a third of a 640x480 frame, a third of the time).
        top, bottom, left, right = self.region_window(intrinsics, table_from_optical)
        rx, ry = rx[left:right], ry[top:bottom]
        rotation = np.asarray(table_from_optical, dtype=np.float64)[:3, :3].astype(np.float32)
        origin = np.asarray(table_from_optical, dtype=np.float64)[:3, 3].astype(np.float32)
        z = depth[top:bottom, left:right].astype(np.float32, copy=False)
        # Table-frame coordinates of every pixel: R @ (rx z, ry z, z) + t, row by row of R.
        def axis(i: int) -> np.ndarray:
            return (rotation[i, 0] * rx[None, :] + rotation[i, 1] * ry[:, None] + rotation[i, 2]) * z + origin[i]

        valid = z > 0.0
        height = axis(2) - np.float32(t.table_height)
        robot = valid & (height > s.max_object_height)
        px, py = axis(0), axis(1)
        m = s.region_margin
        in_region = ((px >= t.region_low[0] - m) & (px <= t.region_high[0] + m)
                     & (py >= t.region_low[1] - m) & (py <= t.region_high[1] + m))
        standing = valid & in_region & (height > s.min_height) & ~robot
        far = _far_side_of_jumps(z, standing, depth_jump) if depth_jump is not None else None
        labels, count = label_components(standing if far is None else standing & ~far)
        # A pixel's footprint seen square-on: (z / f)^2 m^2.
        footprint = (z / np.float32(intrinsics.fx)) * (z / np.float32(intrinsics.fy))
        pieces = Pieces(count, [], [], [], height, px, py, footprint, table_from_optical, intrinsics, z.shape[1])
        if count == 0:
            return pieces
        behind = _labels_behind(labels, z, far, depth_jump) if far is not None else set()
        near_robot = dilate(robot, max(s.robot_margin_px, 1)) if robot.any() else robot
        flat = labels.ravel()
        labelled = np.flatnonzero(flat)
        order = labelled[np.argsort(flat[labelled], kind="stable")]
        bounds = np.searchsorted(flat[order], np.arange(1, count + 2))
        w_img = z.shape[1]
        for label in range(1, count + 1):
            index = order[bounds[label - 1]:bounds[label]]
            rows, cols = np.divmod(index, w_img)
            area = float(footprint.ravel()[index].sum())
            if near_robot.ravel()[index].any() and self._hidden_by_robot(labels == label, robot, z):
                if area >= 0.25 * s.min_area:
                    pieces.occluded.append(index)
                continue
            if (rows.min() + top == 0 or cols.min() + left == 0 or rows.max() + top == depth.shape[0] - 1
                    or cols.max() + left == depth.shape[1] - 1):
                pieces.at_border.append((f"{area * 1e4:.0f} cm^2 at the image border", index))
                continue
            if label in behind:
                pieces.behind.append(index)
                continue
            if not s.min_area <= area <= s.max_area:
                if area >= 0.25 * s.min_area:
                    pieces.rejected.append((f"{area * 1e4:.1f} cm^2", index))
                continue
            pieces.candidates.append(index)
        return pieces

    def measure(self, pieces: "Pieces", index: np.ndarray) -> Detection:
        """The :class:`Detection` of one piece of :meth:`segment` (flat indices into the region window)."""
        height, px, py, footprint = pieces.height, pieces.px, pieces.py, pieces.footprint
        table_from_optical, intrinsics, w_img = pieces.table_from_optical, pieces.intrinsics, pieces.width
        s, table_height = self.settings, self.table.table_height
        heights = height.ravel()[index]
        top_level = float(np.percentile(heights, 90))
        top_face = index[heights >= top_level - s.top_tolerance]
        top_height = float(np.median(height.ravel()[top_face]))
        # Pixel footprints on a plane seen at an angle grow with z^2: weigh by it so the
        # centroid is the face's, not the pixels'.
        weights = footprint.ravel()[top_face].astype(np.float64)
        weights /= weights.sum()
        face_x, face_y = px.ravel()[top_face], py.ravel()[top_face]
        cx = float(weights @ face_x)
        cy = float(weights @ face_y)
        # Equivalent diameter from the face's spread: a disc's radial variance is r^2 / 2.
        radial = (face_x - cx) ** 2 + (face_y - cy) ** 2
        spread = float(weights @ radial)
        size = 2.0 * math.sqrt(2.0 * spread)
        kind, yaw, extents = face_shape(face_x - cx, face_y - cy, weights)
        half = 0.5 * (s.object_height if s.object_height > 0.0 else top_height)
        centre_table = np.array([cx, cy, table_height + top_height - half, 1.0])
        centre_optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ centre_table
        top_optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ np.array(
            [cx, cy, table_height + top_height, 1.0])
        u, v = intrinsics.project(top_optical[:3])
        rows, cols = np.divmod(index, w_img)
        radius = 0.5 * max(rows.max() - rows.min(), cols.max() - cols.min()) + 1.0
        return Detection(tuple(float(c) for c in centre_optical[:3]), tuple(float(c) for c in centre_table[:3]),
                         top_height, (float(u), float(v)), float(radius), int(index.size), size, kind, yaw, extents)

    def _hidden_by_robot(self, piece: np.ndarray, robot: np.ndarray, depth: np.ndarray) -> bool:
        """Whether the robot, where it borders ``piece`` in the image, is not clearly *behind*
        it: in front it hides part of it; at the same depth the piece is the robot's own
        continuation (a finger below ``max_object_height``). Either way its visible part is no
        object's whole top face."""
        margin = max(self.settings.robot_margin_px, 1)
        rows, cols = np.nonzero(piece)
        top, bottom = max(rows.min() - margin, 0), min(rows.max() + margin + 1, piece.shape[0])
        left, right = max(cols.min() - margin, 0), min(cols.max() + margin + 1, piece.shape[1])
        piece, robot, depth = piece[top:bottom, left:right], robot[top:bottom, left:right], depth[top:bottom, left:right]
        h, w = piece.shape
        for dy in range(-margin, margin + 1):
            for dx in range(-margin, margin + 1):
                if dy == 0 and dx == 0:
                    continue
                # piece pixel at (r, c), robot pixel at (r + dy, c + dx)
                p_rows, r_rows = slice(max(-dy, 0), h - max(dy, 0)), slice(max(dy, 0), h - max(-dy, 0))
                p_cols, r_cols = slice(max(-dx, 0), w - max(dx, 0)), slice(max(dx, 0), w - max(-dx, 0))
                pairs = piece[p_rows, p_cols] & robot[r_rows, r_cols]
                if pairs.any() and (depth[r_rows, r_cols][pairs] < depth[p_rows, p_cols][pairs] + 0.01).any():
                    return True
        return False
