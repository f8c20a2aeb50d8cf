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
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from .pinhole import Intrinsics, IntrinsicsError


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


class InputError(ValueError):
    """A message that cannot be turned into an image; carries the :class:`Refusal`."""

    def __init__(self, refusal: Refusal) -> None:
        super().__init__(str(refusal))
        self.refusal = refusal


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
    """

    position: Tuple[float, float, float]
    position_table: Tuple[float, float, float]
    top_height: float
    pixel: Tuple[float, float]
    radius_px: float
    pixels: int
    size: float = 0.0


@dataclass(frozen=True)
class DetectorSettings:
    """What the detector looks for (``config/detector.yaml`` and the table/region of
    ``config/env.yaml``).

    :param region_low: (x, y) low corner (m) of the placement region in the table frame.
    :param region_high: (x, y) high corner (m).
    :param region_margin: m added around the region (an object pushed slightly out still counts).
    :param table_height: z (m) of the table top in the table frame.
    :param min_height: m above the table below which a point is table (depth noise, tilt).
    :param max_object_height: m above the table above which a point is the robot.
    :param top_tolerance: m below the top height that still counts as the top face.
    :param object_height: the object's height (m) when known; 0: estimated from its top
        (valid for an object standing on the table).
    :param min_area: smallest object footprint seen from the camera (m^2).
    :param max_area: largest (m^2).
    :param robot_margin_px: a piece within this many pixels of the robot is occluded.
    :param min_valid_depth_fraction: a frame with less valid depth than this is refused.
    """

    region_low: Tuple[float, float]
    region_high: Tuple[float, float]
    region_margin: float = 0.05
    table_height: float = 0.0
    min_height: float = 0.01
    max_object_height: float = 0.09
    top_tolerance: float = 0.002
    object_height: float = 0.0
    min_area: float = 4.0e-4
    max_area: float = 1.0e-2
    robot_margin_px: int = 2
    min_valid_depth_fraction: float = 0.2


# ----------------------------------------------------------------------------- decoding
COLOR_ENCODINGS = {"rgb8": (3, False), "bgr8": (3, True), "rgba8": (4, False), "bgra8": (4, True)}
DEPTH_ENCODINGS = {"16UC1": (np.dtype("<u2"), 0.001), "mono16": (np.dtype("<u2"), 0.001),
                   "32FC1": (np.dtype("<f4"), 1.0)}


def _buffer(data: bytes, height: int, width: int, step: int, channels: int, dtype: np.dtype,
            big_endian: bool, what: str) -> np.ndarray:
    item = channels * dtype.itemsize
    if height <= 0 or width <= 0 or step < width * item or len(data) < step * height:
        raise InputError(Refusal(RefusalReason.BAD_IMAGE, f"{what} {width}x{height}, step {step}, "
                                                          f"{len(data)} bytes"))
    rows = np.frombuffer(data, dtype=np.uint8, count=step * height).reshape(height, step)[:, :width * item]
    array = np.ascontiguousarray(rows).view(dtype.newbyteorder(">") if big_endian else dtype)
    return array.reshape(height, width, channels) if channels > 1 else array.reshape(height, width)


def decode_color(encoding: str, height: int, width: int, step: int, data: bytes, big_endian: bool = False
                 ) -> np.ndarray:
    """A ``sensor_msgs/Image`` colour image as (H, W, 3) uint8 RGB.

    :raise InputError: an encoding other than rgb8/bgr8/rgba8/bgra8, or data that does not fit.
    """
    if encoding not in COLOR_ENCODINGS:
        raise InputError(Refusal(RefusalReason.ENCODING, f"colour '{encoding}' (takes {', '.join(COLOR_ENCODINGS)})"))
    channels, reverse = COLOR_ENCODINGS[encoding]
    image = _buffer(data, height, width, step, channels, np.dtype(np.uint8), False, "colour")[:, :, :3]
    return image[:, :, ::-1] if reverse else image


def decode_depth(encoding: str, height: int, width: int, step: int, data: bytes, big_endian: bool = False
                 ) -> np.ndarray:
    """A depth image as (H, W) float32 metres, 0 where there is no data (0 in ``16UC1``, NaN or
    inf or <= 0 in ``32FC1``).

    :raise InputError: an encoding other than 16UC1 (mm, the RealSense driver's), mono16 or
        32FC1 (m), or data that does not fit.
    """
    if encoding not in DEPTH_ENCODINGS:
        raise InputError(Refusal(RefusalReason.ENCODING, f"depth '{encoding}' (takes {', '.join(DEPTH_ENCODINGS)})"))
    dtype, scale = DEPTH_ENCODINGS[encoding]
    raw = _buffer(data, height, width, step, 1, dtype, big_endian, "depth")
    depth = raw.astype(np.float32) * np.float32(scale)
    depth[~np.isfinite(depth) | (depth < 0.0)] = 0.0
    return depth


def intrinsics_from_camera_info(width: int, height: int, k: Sequence[float], p: Sequence[float]) -> Intrinsics:
    """:meth:`Intrinsics.from_camera_info`, refusals as :class:`InputError`."""
    try:
        return Intrinsics.from_camera_info(width, height, k, p)
    except IntrinsicsError as error:
        raise InputError(Refusal(RefusalReason.CAMERA_INFO, str(error))) from None


def check_frame(color: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, stamp: float, now: float,
                timeout: float, min_valid_fraction: float) -> Optional[Refusal]:
    """The checks every frame passes before detection; None when it is usable.

    :param stamp: the images' capture time (s).
    :param now: the current time on the same clock (s).
    :param timeout: s; an older frame is refused.
    """
    shapes = {"colour": color.shape[:2], "depth": depth.shape[:2],
              "camera_info": (intrinsics.height, intrinsics.width)}
    if len(set(shapes.values())) != 1:
        return Refusal(RefusalReason.SIZE_MISMATCH, ", ".join(f"{k} {w}x{h}" for k, (h, w) in shapes.items()))
    if now - stamp > timeout:
        return Refusal(RefusalReason.STALE, f"{now - stamp:.3f} s old > {timeout:g} s")
    valid = float(np.count_nonzero(depth > 0.0)) / depth.size
    if valid < min_valid_fraction:
        return Refusal(RefusalReason.DEPTH_INVALID, f"{valid:.0%} of the pixels have depth "
                                                    f"(needs {min_valid_fraction:.0%}; all zero or NaN?)")
    return None


# ----------------------------------------------------------------------------- image helpers
def label_components(mask: np.ndarray) -> Tuple[np.ndarray, int]:
    """8-connected components of a boolean image: labels (H, W) int32 (0 = background, 1..n)
    and n. Runs of each row are joined with the overlapping runs of the row above (union-find
    over runs: the loop is over runs, not pixels)."""
    height, width = mask.shape
    padded = np.zeros((height, width + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    edges = np.diff(padded, axis=1)
    rows_s, starts = np.nonzero(edges == 1)
    _, ends = np.nonzero(edges == -1)  # exclusive; same order as the starts (row-major)
    count = len(starts)
    labels = np.zeros((height, width), dtype=np.int32)
    if count == 0:
        return labels, 0
    parent = list(range(count))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    row_first = np.searchsorted(rows_s, np.arange(height + 1))
    rows_l, starts_l, ends_l = rows_s.tolist(), starts.tolist(), ends.tolist()
    for i in range(count):
        row = rows_l[i]
        if row == 0:
            continue
        for j in range(row_first[row - 1], row_first[row]):
            # 8-connected: runs touch if they overlap once widened by one pixel.
            if starts_l[j] <= ends_l[i] and starts_l[i] <= ends_l[j]:
                a, b = find(i), find(j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    roots = np.array([find(i) for i in range(count)])
    _, compact = np.unique(roots, return_inverse=True)
    for i in range(count):
        labels[rows_l[i], starts_l[i]:ends_l[i]] = compact[i] + 1
    return labels, int(compact.max()) + 1


def dilate(mask: np.ndarray, pixels: int) -> np.ndarray:
    """``mask`` grown by ``pixels`` (a square neighbourhood)."""
    grown = mask.copy()
    for _ in range(pixels):
        step = grown.copy()
        step[1:, :] |= grown[:-1, :]
        step[:-1, :] |= grown[1:, :]
        step[:, 1:] |= grown[:, :-1]
        step[:, :-1] |= grown[:, 1:]
        grown = step
    return grown


# ----------------------------------------------------------------------------- detection
class ObjectDetector:
    """The object in a frame, given the camera model and the camera's pose over the table.

    :param settings: see :class:`DetectorSettings`.
    """

    def __init__(self, settings: DetectorSettings) -> None:
        self.settings = settings
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
        s = self.settings
        key = (intrinsics, np.asarray(table_from_optical, dtype=np.float64).tobytes())
        if self._window is not None and self._window[0] == key:
            return self._window[1]
        m = s.region_margin
        corners = np.array([[x, y, s.table_height + h, 1.0]
                            for x in (s.region_low[0] - m, s.region_high[0] + m)
                            for y in (s.region_low[1] - m, s.region_high[1] + m)
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
            (z up, the table top at ``settings.table_height``).
        :param color: (H, W, 3) uint8, unused by the geometry (kept for optional colour filters).
        :return: the :class:`Detection`, or the :class:`Refusal` saying why there is none.
        """
        s = self.settings
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
        height = axis(2) - np.float32(s.table_height)
        robot = valid & (height > s.max_object_height)
        px, py = axis(0), axis(1)
        m = s.region_margin
        in_region = ((px >= s.region_low[0] - m) & (px <= s.region_high[0] + m)
                     & (py >= s.region_low[1] - m) & (py <= s.region_high[1] + m))
        standing = valid & in_region & (height > s.min_height) & ~robot
        labels, count = label_components(standing)
        if count == 0:
            return Refusal(RefusalReason.NO_OBJECT, "nothing stands on the table in the region")
        near_robot = dilate(robot, max(s.robot_margin_px, 1)) if robot.any() else robot
        flat = labels.ravel()
        labelled = np.flatnonzero(flat)
        order = labelled[np.argsort(flat[labelled], kind="stable")]
        bounds = np.searchsorted(flat[order], np.arange(1, count + 2))
        # A pixel's footprint seen square-on: (z / f)^2 m^2.
        footprint = (z / np.float32(intrinsics.fx)) * (z / np.float32(intrinsics.fy))
        candidates: List[np.ndarray] = []
        occluded, rejected = 0, []
        h_img, w_img = z.shape
        for label in range(1, count + 1):
            index = order[bounds[label - 1]:bounds[label]]
            rows, cols = np.divmod(index, w_img)
            area = float(footprint.ravel()[index].sum())
            if near_robot.ravel()[index].any() and self._hidden_by_robot(labels == label, robot, z):
                if area >= 0.25 * s.min_area:
                    occluded += 1
                continue
            if (rows.min() + top == 0 or cols.min() + left == 0 or rows.max() + top == depth.shape[0] - 1
                    or cols.max() + left == depth.shape[1] - 1):
                rejected.append(f"{area * 1e4:.0f} cm^2 at the image border")
                continue
            if not s.min_area <= area <= s.max_area:
                if area >= 0.25 * s.min_area:
                    rejected.append(f"{area * 1e4:.1f} cm^2")
                continue
            candidates.append(index)
        if not candidates:
            if occluded:
                return Refusal(RefusalReason.OCCLUDED, f"{occluded} piece(s) next to the robot")
            return Refusal(RefusalReason.NO_OBJECT, "pieces rejected: " + ", ".join(rejected) if rejected
                           else "only pieces too small to be the object")
        found = [self._measure(index, height, px, py, footprint, table_from_optical, intrinsics, w_img)
                 for index in candidates]
        if len(found) > 1:
            return Refusal(RefusalReason.SEVERAL_OBJECTS, f"{len(found)} candidates", tuple(found))
        return found[0]

    def _measure(self, index: np.ndarray, height: np.ndarray, px: np.ndarray, py: np.ndarray,
                 footprint: np.ndarray, table_from_optical: np.ndarray, intrinsics: Intrinsics,
                 w_img: int) -> Detection:
        """The :class:`Detection` of one candidate piece (flat indices into the region window)."""
        s = self.settings
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
        spread = float(weights @ ((face_x - cx) ** 2 + (face_y - cy) ** 2))
        size = 2.0 * math.sqrt(2.0 * spread)
        half = 0.5 * (s.object_height if s.object_height > 0.0 else top_height)
        centre_table = np.array([cx, cy, s.table_height + top_height - half, 1.0])
        centre_optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ centre_table
        top_optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ np.array(
            [cx, cy, s.table_height + top_height, 1.0])
        u, v = intrinsics.project(top_optical[:3])
        rows, cols = np.divmod(index, w_img)
        radius = 0.5 * max(rows.max() - rows.min(), cols.max() - cols.min()) + 1.0
        return Detection(tuple(float(c) for c in centre_optical[:3]), tuple(float(c) for c in centre_table[:3]),
                         top_height, (float(u), float(v)), float(radius), int(index.size), size)


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


# ----------------------------------------------------------------------------- tracking
# Refusals about what the frame shows (the others are about the frame itself).
SCENE_REFUSALS = (RefusalReason.NO_OBJECT, RefusalReason.SEVERAL_OBJECTS, RefusalReason.OCCLUDED)


class TrackState(enum.Enum):
    """Where a published object position comes from."""

    SEEN = "seen"            # detected in this very frame
    HIDDEN = "hidden"        # the robot hides it: its last seen position, for a bounded time
    IN_HAND = "in hand"      # the fingers hold it: it moves with the tcp


@dataclass(frozen=True)
class TrackedObject:
    """The object position to publish for one frame.

    :param position_table: object centre (m) in the table frame.
    :param state: why this position is believed (:class:`TrackState`).
    :param last_seen: stamp (s) of the frame that last detected it (or in which the hand let it go).
    :param detection: this frame's detection (state SEEN), else None.
    :param position_tcp: in the hand: the centre (m) in the tcp frame (it moves with the tcp).
    """

    position_table: Tuple[float, float, float]
    state: TrackState
    last_seen: float
    detection: Optional[Detection] = None
    position_tcp: Optional[Tuple[float, float, float]] = None


@dataclass(frozen=True)
class TrackerSettings:
    """How long and under which evidence a hidden object is still believed where it was
    (``config/detector.yaml``).

    :param hidden_timeout: s after the last sighting during which a hidden object's last position
        is still published; 0 switches tracking off (every hidden frame holds).
    :param in_hand_timeout: s after the last sighting during which an object held between the
        fingers is published at the tcp (a slipping object cannot be told from a held one).
    :param max_table_fraction: where the last seen top face was, at most this fraction of the
        pixels may show the bare table; more means the object has gone (hold).
    :param front_tolerance: m; a depth this much nearer than the top face is something in front of it.
    :param grasp_radius: m; the fingers hold the object only if the tcp is this close to its centre.
    :param grasp_width_margin: m; the fingers are closed on it when their opening is at most the
        object's measured width plus this (and more than ``min_grasp_fraction`` of it).
    :param min_grasp_fraction: fingers closed narrower than this fraction of the object's
        measured width have nothing between them (a held object yields a little, not by half).
    :param closing_tolerance: m; fingers that closed by more than this since the last frame are
        still closing: the object is taken into the hand only once they stop on it (earlier, the
        tcp may still move relative to it).
    :param closing_axis: the direction (tcp frame) the fingers close along. Closing fingers push
        the object to their middle, so in the hand its offset along this axis is 0.
    :param gate_height: m; while an object is tracked, a detection whose top differs from its
        standing top height by more than this is a part of it (a finger hides the rest): hidden.
    :param gate_size: likewise for a top face width that differs by more than this fraction.
    :param nudge_radius: m; fingers closing or pressing beside a hidden object push it a little.
        Where its top face was shows bare table, the tracker looks for that face up to this far
        away (still hidden by something in front of it) before it drops the track; 0: never.
    :param nudge_step: m between the positions it looks at.
    """

    hidden_timeout: float = 2.0
    in_hand_timeout: float = 10.0
    max_table_fraction: float = 0.25
    front_tolerance: float = 0.01
    grasp_radius: float = 0.04
    grasp_width_margin: float = 0.01
    min_grasp_fraction: float = 0.5
    closing_tolerance: float = 0.002
    closing_axis: Tuple[float, float, float] = (0.0, 1.0, 0.0)
    gate_height: float = 0.01
    gate_size: float = 0.3
    nudge_radius: float = 0.03
    nudge_step: float = 0.005


def footprint_view(depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
                   settings: DetectorSettings, centre_table: Sequence[float], top_height: float,
                   size: float, front_tolerance: float) -> Tuple[float, float, int]:
    """What the camera sees where an object's top face was: the fractions of its pixels with
    something in front of that face, and with the bare table (the object has gone).

    :param depth: (H, W) float metres along the optical axis, 0 = no data.
    :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame.
    :param centre_table: the object's centre (m, table frame); only x, y are used.
    :param top_height: its top face's height (m) above the table.
    :param size: its top face's width (m).
    :param front_tolerance: m; nearer than the face by more than this is in front of it.
    :return: ``(in_front, table, samples)``: fractions of the face's sample points that lie in
        the image with depth, and how many those were (0: the face is out of view).
    """
    in_front, table, samples = footprint_views(depth, intrinsics, table_from_optical, settings,
                                               np.asarray(centre_table, dtype=np.float64)[None, :2], top_height,
                                               size, front_tolerance)
    return float(in_front[0]), float(table[0]), int(samples[0])


def footprint_views(depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
                    settings: DetectorSettings, centres_xy: np.ndarray, top_height: float, size: float,
                    front_tolerance: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`footprint_view` for N candidate centres (N, 2) at once: arrays of N ``in_front``,
    ``table`` and ``samples``."""
    # Rings over the face, not its rim only: a finger in front of the rim still leaves the centre.
    radii = np.array([0.0, 0.3, 0.6, 0.85]) * (0.5 * size)
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    r, a = np.meshgrid(radii, angles)
    offsets = np.stack([(r * np.cos(a)).ravel(), (r * np.sin(a)).ravel()], axis=1)
    centres_xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    n, m = len(centres_xy), len(offsets)
    xy = (centres_xy[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    points = np.stack([xy[:, 0], xy[:, 1], np.full(n * m, settings.table_height + top_height), np.ones(n * m)])
    table_from_optical = np.asarray(table_from_optical, dtype=np.float64)
    optical = np.linalg.inv(table_from_optical) @ points
    expected = optical[2]
    used = expected > 1e-6  # in front of the camera, then: in the image, then: with depth
    u = np.full(n * m, -1)
    v = np.full(n * m, -1)
    pixels = intrinsics.project(optical[:3, used].T)
    u[used], v[used] = np.rint(pixels[:, 0]).astype(int), np.rint(pixels[:, 1]).astype(int)
    used &= (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    measured = np.zeros(n * m)
    measured[used] = depth[v[used], u[used]]
    used &= measured > 0.0
    rx, ry = intrinsics.ray(u, v)
    seen_height = (table_from_optical[2] @ np.stack([rx * measured, ry * measured, measured, np.ones(n * m)])
                   - settings.table_height)
    in_front = used & (measured < expected - front_tolerance)
    table = used & (seen_height < settings.min_height) & ~in_front
    samples = used.reshape(n, m).sum(axis=1)
    share = lambda mask: np.where(samples > 0, mask.reshape(n, m).sum(axis=1) / np.maximum(samples, 1), 0.0)  # noqa: E731
    return share(in_front), share(table), samples


class ObjectTracker:
    """Bridges the frames in which the robot hides the object it is about to grasp or holds.

    The detector refuses a hidden object (its visible part would give a biased centre), and
    it must: but the gripper hides the object exactly when the grasp policy needs it, going
    down around it, closing and lifting. A robot knows two more things than the camera: the
    object does not move on its own while the arm covers it, and once the fingers are closed
    on it, it moves with them. So, per frame:

    - detected: that position (SEEN);
    - the fingers have closed on it (their opening at most its measured width plus
      ``grasp_width_margin``, more than ``min_grasp_fraction`` of it, and no longer closing) with the
      tcp within ``grasp_radius`` of it: it is in the hand (IN_HAND). Its offset in the tcp
      frame is kept and published *in the tcp frame*, so whoever uses it places it with the
      newest tcp pose: no camera latency on a held object. It stays in the hand until the
      fingers open or close on nothing, where it would be the camera sees the bare table, or
      ``in_hand_timeout``;
    - not detected because something hides it (the refusal is OCCLUDED or NO_OBJECT, and where
      its top face was, the camera sees something in front of it rather than the bare table):
      its last position, for ``hidden_timeout`` after the last sighting (HIDDEN);
    - several candidates: those not the whole object (a top lower, higher, narrower or wider
      than its own: finger tips, a part of it) are set aside, and the rest is judged as above;
    - otherwise: hold. Several whole candidates, a bare table where it stood, or a timeout drop
      the track.

    Nothing here knows the object's colour. Pure numpy; the node feeds it each frame's
    result, the tcp pose and the gripper opening.

    :param settings: see :class:`TrackerSettings`.
    :param detector_settings: the detector's (table height, min_height) for :func:`footprint_view`.
    """

    def __init__(self, settings: TrackerSettings, detector_settings: DetectorSettings) -> None:
        self.settings = settings
        self.detector_settings = detector_settings
        self._last_width: Optional[float] = None
        self.reset()

    def reset(self) -> None:
        """Forget the object (a new one will be detected before anything is published)."""
        self._position: Optional[np.ndarray] = None  # table frame, m
        self._top_height = 0.0
        self._size = 0.0
        self._last_seen = 0.0
        self._in_tcp: Optional[np.ndarray] = None  # object centre in the tcp frame while held
        self._in_front = 0.0  # fraction of its last look with something in front of it
        self._rest = (0.0, 0.0)  # centre height (m, table frame) and top height when it stands on the table

    @property
    def state(self) -> Optional[TrackState]:
        """None when no object is tracked."""
        if self._position is None:
            return None
        return TrackState.IN_HAND if self._in_tcp is not None else TrackState.HIDDEN

    def update(self, result: Union[Detection, Refusal], stamp: float, depth: Optional[np.ndarray] = None,
               intrinsics: Optional[Intrinsics] = None, table_from_optical: Optional[np.ndarray] = None,
               table_from_tcp: Optional[np.ndarray] = None, gripper_width: Optional[float] = None
               ) -> Union[TrackedObject, Refusal]:
        """The position to publish for one frame, or why to hold.

        :param result: the detector's answer for the frame.
        :param stamp: the frame's capture time (s).
        :param depth: the frame's depth (m), for the look at where a hidden object was.
        :param intrinsics: its camera model.
        :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame.
        :param table_from_tcp: 4x4 pose (m) of the tcp in the table frame at ``stamp``; None
            when unknown (no in-hand tracking).
        :param gripper_width: the fingers' opening (m) at ``stamp``; None when unknown.
        """
        if isinstance(result, Refusal) and result.reason not in SCENE_REFUSALS:
            return result  # a frame that could not be looked at says nothing about the object
        tcp = None if table_from_tcp is None else np.asarray(table_from_tcp, dtype=np.float64)
        closing = (gripper_width is not None and self._last_width is not None
                   and self._last_width - gripper_width > self.settings.closing_tolerance)
        self._last_width = gripper_width
        look = (depth, intrinsics, table_from_optical) if depth is not None and intrinsics is not None \
            and table_from_optical is not None else None
        if self._in_tcp is not None:
            return self._follow_hand(result, stamp, look, tcp, gripper_width)
        if self._position is not None and isinstance(result, Refusal) and result.candidates:
            result = self._sort_out(result)
        if isinstance(result, Detection) and self._position is not None:
            partial = self._partial(result)
            if partial is not None:
                result = Refusal(RefusalReason.OCCLUDED, partial)
        if isinstance(result, Detection):
            self._position = np.array(result.position_table, dtype=np.float64)
            self._top_height, self._size, self._last_seen = result.top_height, result.size, stamp
            self._rest = (float(self._position[2]), result.top_height)  # seen: standing on the table
            return TrackedObject(tuple(self._position.tolist()), TrackState.SEEN, stamp, result)
        if self._position is None:
            return result
        if result.reason is RefusalReason.SEVERAL_OBJECTS:
            self.reset()
            return result
        s = self.settings
        age = stamp - self._last_seen
        if age > s.hidden_timeout:
            self.reset()
            return Refusal(result.reason, f"{result.detail}; hidden for {age:.1f} s > hidden_timeout "
                                          f"{s.hidden_timeout:g} s")
        if look is None:
            return result
        gone = self._gone(look)
        if gone is not None and not self._nudged(look):
            self.reset()
            return Refusal(result.reason, f"{result.detail}; {gone}")
        if result.reason is RefusalReason.NO_OBJECT and self._in_front == 0.0:
            return result  # nothing in front of it and no object: not hidden, it was just not found
        if not closing and self._closed_on_it(tcp, gripper_width):
            self._take_into_hand(tcp)
            return self._held(TrackState.IN_HAND)
        return self._held(TrackState.HIDDEN)

    def _follow_hand(self, result: Union[Detection, Refusal], stamp: float, look, tcp: Optional[np.ndarray],
                     width: Optional[float]) -> Union[TrackedObject, Refusal]:
        s = self.settings
        if tcp is not None:
            self._place((tcp @ np.append(self._in_tcp, 1.0))[:3], tcp)
        if isinstance(result, Detection) and self._far(result.position_table):
            self.reset()
            return Refusal(RefusalReason.SEVERAL_OBJECTS, "an object in the hand and one elsewhere")
        if tcp is None or width is None or not self._fits(width):
            # Let go (or closed on nothing): it stands on the table below where the hand left
            # it, as sure as a sighting; if it fell elsewhere, the look at its top face tells.
            self._in_tcp = None
            self._last_seen = stamp
            self._position[2], self._top_height = self._rest
            return self._held(TrackState.HIDDEN)
        if stamp - self._last_seen > s.in_hand_timeout:
            self.reset()
            return Refusal(RefusalReason.OCCLUDED, f"in the hand, unseen for more than in_hand_timeout "
                                                   f"{s.in_hand_timeout:g} s")
        gone = self._gone(look) if look is not None else None
        if gone is not None:
            self.reset()
            return Refusal(RefusalReason.NO_OBJECT, f"not in the hand any more: {gone}")
        return self._held(TrackState.IN_HAND)

    def _take_into_hand(self, tcp: np.ndarray) -> None:
        in_tcp = (np.linalg.inv(tcp) @ np.append(self._position, 1.0))[:3]
        axis = np.asarray(self.settings.closing_axis, dtype=np.float64)
        axis /= np.linalg.norm(axis)
        self._in_tcp = in_tcp - float(in_tcp @ axis) * axis  # centred between the fingers
        self._place((tcp @ np.append(self._in_tcp, 1.0))[:3], tcp)

    def _place(self, position: np.ndarray, tcp: np.ndarray) -> None:
        # The table holds it up: a tcp pressing lower slides the fingers along it.
        position = np.array(position, dtype=np.float64)
        if position[2] < self._rest[0]:
            position[2] = self._rest[0]
            self._in_tcp = (np.linalg.inv(tcp) @ np.append(position, 1.0))[:3]
        self._top_height = self._rest[1] + float(position[2] - self._rest[0])
        self._position = position

    def _sort_out(self, several: Refusal) -> Union[Detection, Refusal]:
        """Several candidates while an object is tracked: finger tips lower than
        ``max_object_height`` beside it, or pieces of it between the fingers, stand on the table
        like objects. Those that are not the whole object (:meth:`_partial`) are not another
        one: the one whole candidate is the object; none, and it is hidden among them; more
        than one, and which is which cannot be told."""
        whole = [c for c in several.candidates if self._partial(c) is None]
        if len(whole) == 1:
            return whole[0]
        if not whole:
            return Refusal(RefusalReason.OCCLUDED, f"{len(several.candidates)} pieces, none of them the whole "
                                                   f"object: parts of it and of the fingers")
        return several

    def _partial(self, detection: Detection) -> Optional[str]:
        """Why a detection cannot be the whole tracked object (its top lower or higher, or its
        face narrower or wider, than the object's when it was last seen standing: a part of it
        beside a finger, or a finger tip), or None."""
        s = self.settings
        rest_top = self._rest[1]
        if abs(detection.top_height - rest_top) > s.gate_height:
            return (f"a piece {detection.top_height * 100:.1f} cm high where the object stands "
                    f"{rest_top * 100:.1f} cm: part of it (gate_height {s.gate_height:g} m)")
        if self._size > 0.0 and abs(detection.size / self._size - 1.0) > s.gate_size:
            return (f"a piece {detection.size * 100:.1f} cm wide where the object is {self._size * 100:.1f} cm: "
                    f"part of it (gate_size {s.gate_size:g})")
        return None

    def _gone(self, look) -> Optional[str]:
        """Why the camera says the object is not where it is believed to be, or None."""
        depth, intrinsics, table_from_optical = look
        self._in_front, table, samples = footprint_view(
            depth, intrinsics, table_from_optical, self.detector_settings, self._position, self._top_height,
            self._size, self.settings.front_tolerance)
        if samples == 0:
            return "where it should be is out of view"
        if table > self.settings.max_table_fraction:
            return f"where it should be the table is bare ({table:.0%} of its top face)"
        return None

    def _nudged(self, look) -> bool:
        """Where the hidden object's top face would be after a push of up to ``nudge_radius``:
        the place with the least bare table among those where something stands in front of the
        face (the hand that pushed it) and at most ``max_table_fraction`` of it shows the table,
        the nearest on a tie. Moves the track there; False (the track unchanged) when none is."""
        s = self.settings
        if s.nudge_radius <= 0.0 or s.nudge_step <= 0.0:
            return False
        depth, intrinsics, table_from_optical = look
        steps = np.arange(-int(s.nudge_radius // s.nudge_step), int(s.nudge_radius // s.nudge_step) + 1)
        shifts = np.stack(np.meshgrid(steps, steps), axis=-1).reshape(-1, 2) * s.nudge_step
        distance = np.hypot(shifts[:, 0], shifts[:, 1])
        around = (distance > 0.0) & (distance <= s.nudge_radius + 1e-9)
        shifts, distance = shifts[around], distance[around]
        in_front, table, samples = footprint_views(depth, intrinsics, table_from_optical, self.detector_settings,
                                                   self._position[:2] + shifts, self._top_height, self._size,
                                                   s.front_tolerance)
        fits = np.flatnonzero((samples > 0) & (in_front > 0.0) & (table <= s.max_table_fraction))
        if fits.size == 0:
            return False
        best = fits[np.lexsort((distance[fits], table[fits]))[0]]
        self._position = self._position.copy()
        self._position[:2] += shifts[best]
        self._in_front = float(in_front[best])
        return True

    def _held(self, state: TrackState) -> TrackedObject:
        in_tcp = tuple(self._in_tcp.tolist()) if state is TrackState.IN_HAND else None
        return TrackedObject(tuple(self._position.tolist()), state, self._last_seen, None, in_tcp)

    def _closed_on_it(self, tcp: Optional[np.ndarray], width: Optional[float]) -> bool:
        s = self.settings
        if tcp is None or width is None or self._position is None:
            return False
        closed_on_it = self._fits(width)
        return closed_on_it and float(np.linalg.norm(tcp[:3, 3] - self._position)) <= s.grasp_radius

    def _fits(self, width: float) -> bool:
        # The fingers' opening (m) with the object between them.
        s = self.settings
        return s.min_grasp_fraction * self._size < width <= self._size + s.grasp_width_margin

    def _far(self, position_table: Sequence[float]) -> bool:
        # A detection this far from the held object's centre is another object.
        return float(np.linalg.norm(np.subtract(position_table, self._position)[:2])) > self.settings.grasp_radius


TRACK_COLOURS = {TrackState.SEEN: (0, 255, 0), TrackState.HIDDEN: (255, 220, 0), TrackState.IN_HAND: (0, 160, 255)}


def draw_detection(color: np.ndarray, result: Union[Detection, TrackedObject, Refusal],
                   intrinsics: Optional[Intrinsics] = None, table_from_optical: Optional[np.ndarray] = None
                   ) -> np.ndarray:
    """A copy of ``color`` with the detection drawn (the debug image): a ring and cross at the
    object, green when seen in this frame, yellow when hidden (its last position), blue when in
    the hand; a red frame round the image when there is none.

    :param intrinsics: the camera model, to place a position that was not seen this frame.
    :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame, likewise.
    """
    image = np.array(color, dtype=np.uint8, copy=True)
    h, w = image.shape[:2]
    if isinstance(result, Refusal):
        image[:4, :] = image[-4:, :] = (255, 0, 0)
        image[:, :4] = image[:, -4:] = (255, 0, 0)
        return image
    colour = TRACK_COLOURS[TrackState.SEEN]
    if isinstance(result, TrackedObject):
        colour = TRACK_COLOURS[result.state]
        if result.detection is not None:
            result = result.detection
        elif intrinsics is None or table_from_optical is None:
            return image
        else:
            optical = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64)) @ np.append(
                result.position_table, 1.0)
            if optical[2] <= 0.0:
                return image
            u, v = intrinsics.project(optical[:3])
            _ring(image, float(u), float(v), 20.0, colour)
            return image
    u, v = result.pixel
    _ring(image, u, v, result.radius_px + 4.0, colour)
    return image


def _ring(image: np.ndarray, u: float, v: float, radius: float, colour: Tuple[int, int, int]) -> None:
    h, w = image.shape[:2]
    angles = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    for r in (radius, radius + 1.0, radius + 2.0):
        cols = np.clip(np.rint(u + r * np.cos(angles)).astype(int), 0, w - 1)
        rows = np.clip(np.rint(v + r * np.sin(angles)).astype(int), 0, h - 1)
        image[rows, cols] = colour
    ui, vi = int(round(u)), int(round(v))
    if 0 <= ui < w and 0 <= vi < h:
        image[max(vi - 1, 0):vi + 2, max(ui - 8, 0):ui + 9] = colour
        image[max(vi - 8, 0):vi + 9, max(ui - 1, 0):ui + 2] = colour
