"""Track ids for every object of a scene, frame after frame (issue #54).

:func:`~fr5_rl.perception.scene_detector.detect_scene` sees each frame alone. A cell that picks
"object 3" needs it to stay object 3 while the arm passes over it and hides it for a moment.
:class:`SceneTracker` gives each object found an id, and keeps it:

- from frame to frame, for the object of the same kind nearest to where the track was (within
  ``gate``);
- through frames that do not show it, for ``hidden_timeout`` after it was last seen (the arm in
  front of it, or it refused for a frame). It then gets its id back where it was.

An object seen nowhere near a track gets a new id. Ids are never reused.

Pure numpy, like the detector it follows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Tuple

from .scene_detector import SceneDetection, SceneObjectFound


@dataclass
class SceneTrack:
    """One object followed across frames.

    :param id: its id (1, 2, ...).
    :param label: its kind.
    :param position: its centre (m, table frame) when last seen.
    :param last_seen: when (s, the frames' clock).
    """

    id: int
    label: str
    position: Tuple[float, float, float]
    last_seen: float


class SceneTracker:
    """Ids for the objects of successive frames.

    :param gate: m in the table plane: an object this near where a track of its kind was last
        seen is that track's object.
    :param hidden_timeout: s a track lasts unseen (``config/detector.yaml`` tracker ``hidden_timeout``).
    """

    def __init__(self, gate: float, hidden_timeout: float) -> None:
        if not gate > 0.0 or hidden_timeout < 0.0:
            raise ValueError(f"scene tracker: gate must be positive and hidden_timeout >= 0, got {gate}, {hidden_timeout}")
        self.gate, self.hidden_timeout = gate, hidden_timeout
        self.tracks: Dict[int, SceneTrack] = {}
        self._next_id = 1

    def update(self, scene: SceneDetection, stamp: float) -> List[Tuple[int, SceneObjectFound]]:
        """Each object of a frame with its id.

        :param scene: the frame's objects.
        :param stamp: the frame's capture time (s).
        :return: ``(id, object)`` for each object of ``scene``, in its order.
        """
        for track_id in [i for i, track in self.tracks.items() if stamp - track.last_seen > self.hidden_timeout]:
            del self.tracks[track_id]
        # Nearest pairs first: each track and each object taken once.
        pairs = []
        for index, found in enumerate(scene.objects):
            for track_id, track in self.tracks.items():
                distance = _planar_distance(track.position, found.detection.position_table)
                if track.label == found.label and distance <= self.gate:
                    pairs.append((distance, track_id, index))
        pairs.sort()
        ids: Dict[int, int] = {}
        taken = set()
        for _, track_id, index in pairs:
            if index in ids or track_id in taken:
                continue
            ids[index] = track_id
            taken.add(track_id)
        result = []
        for index, found in enumerate(scene.objects):
            track_id = ids.get(index)
            if track_id is None:
                track_id, self._next_id = self._next_id, self._next_id + 1
            self.tracks[track_id] = SceneTrack(track_id, found.label, tuple(found.detection.position_table), stamp)
            result.append((track_id, found))
        return result

    def reset(self) -> None:
        """Forget every track (ids go on from where they were: never reused)."""
        self.tracks.clear()


def _planar_distance(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])
