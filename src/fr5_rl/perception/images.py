"""Turning ``sensor_msgs/Image`` and ``CameraInfo`` contents into arrays and a camera model, and
the checks every frame passes before detection (pure numpy: the node hands over the message
fields, so nothing here needs ROS).

Anything that cannot be turned into an image raises :class:`InputError`, which carries the
:class:`~fr5_rl.perception.detector.Refusal` the node reports.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from .camera_model import Intrinsics, IntrinsicsError
from .detector import Refusal, RefusalReason


class InputError(ValueError):
    """A message that cannot be turned into an image; carries the :class:`Refusal`."""

    def __init__(self, refusal: Refusal) -> None:
        super().__init__(str(refusal))
        self.refusal = refusal


# Colour encodings taken: (channels, whether the channels are BGR rather than RGB).
COLOR_ENCODINGS = {"rgb8": (3, False), "bgr8": (3, True), "rgba8": (4, False), "bgra8": (4, True)}
# Depth encodings taken: (little-endian sample type, metres per unit).
DEPTH_ENCODINGS = {"16UC1": (np.dtype("<u2"), 0.001), "mono16": (np.dtype("<u2"), 0.001),
                   "32FC1": (np.dtype("<f4"), 1.0)}


def _buffer(data: bytes, height: int, width: int, step: int, channels: int, dtype: np.dtype,
            big_endian: bool, what: str) -> np.ndarray:
    """The (H, W[, C]) array of an image message's bytes, row padding dropped.

    :param step: bytes per row (at least ``width`` samples; more is padding).
    :param what: the image's name in the refusal ("colour", "depth").
    :raise InputError: a size or step the data does not fill (``BAD_IMAGE``).
    """
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

    :param encoding: the message's ``encoding``.
    :param height: rows (pixels).
    :param width: columns (pixels).
    :param step: bytes per row.
    :param data: the pixel bytes.
    :param big_endian: the message's ``is_bigendian`` (no effect on 8-bit samples).
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

    :param encoding: the message's ``encoding``.
    :param height: rows (pixels).
    :param width: columns (pixels).
    :param step: bytes per row.
    :param data: the pixel bytes.
    :param big_endian: the message's ``is_bigendian``.
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
    """:meth:`Intrinsics.from_camera_info`, refusals as :class:`InputError` (``CAMERA_INFO``).

    :param width: the CameraInfo's width (pixels).
    :param height: its height (pixels).
    :param k: its 3x3 ``K``, row-major (pixels).
    :param p: its 3x4 ``P``, row-major; used when set.
    """
    try:
        return Intrinsics.from_camera_info(width, height, k, p)
    except IntrinsicsError as error:
        raise InputError(Refusal(RefusalReason.CAMERA_INFO, str(error))) from None


def check_frame(color: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, stamp: float, now: float,
                timeout: float, min_valid_fraction: float) -> Optional[Refusal]:
    """The checks every frame passes before detection; None when it is usable.

    :param color: (H, W, 3) uint8 RGB.
    :param depth: (H, W) float metres, 0 = no data.
    :param intrinsics: the CameraInfo's model; its size must be the images'.
    :param stamp: the images' capture time (s).
    :param now: the current time on the same clock (s).
    :param timeout: s; an older frame is refused.
    :param min_valid_fraction: a frame with a smaller fraction of its pixels with depth is refused.
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
