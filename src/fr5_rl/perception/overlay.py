"""The debug image: a frame's colour image with what the detector and the tracker made of it
drawn over it, for people (pure numpy: no OpenCV).
"""
from __future__ import annotations

from typing import Optional, Tuple, Union

import numpy as np

from .camera_model import Intrinsics
from .detector import Detection, Refusal
from .tracker import TrackedObject, TrackState

# RGB of the ring per track state: green seen, yellow hidden, blue in the hand.
TRACK_COLOURS = {TrackState.SEEN: (0, 255, 0), TrackState.HIDDEN: (255, 220, 0), TrackState.IN_HAND: (0, 160, 255)}


def draw_detection(color: np.ndarray, result: Union[Detection, TrackedObject, Refusal],
                   intrinsics: Optional[Intrinsics] = None, table_from_optical: Optional[np.ndarray] = None
                   ) -> np.ndarray:
    """A copy of ``color`` with the detection drawn (the debug image): a ring and cross at the
    object, green when seen in this frame, yellow when hidden (its last position), blue when in
    the hand; a red frame round the image when there is none.

    :param color: (H, W, 3) uint8 RGB.
    :param result: the frame's detector or tracker answer.
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
    """Draw a 3-pixel ring of ``radius`` (pixels) round (u, v), and a cross at (u, v), in place."""
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
