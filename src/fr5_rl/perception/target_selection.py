"""One object of a scene as the target: chosen by rule, then followed into the hand and out of it
(issue #54).

The single-object detector refuses a second object on the table; a cell that clears a table
sees several at once. :class:`SceneTargetTracker` sits between the scene's detections and the
one-object :class:`~fr5_rl.perception.tracker.ObjectTracker` the policy's target comes from:

- with no object tracked, it chooses one among those not yet placed (outside
  ``config/clearing.yaml``'s drop area) by the rule (:func:`fr5_rl.clearing.choose_next`:
  ``nearest``, ``kind``; or ``id``, a track id of :class:`~fr5_rl.perception.scene_tracker.SceneTracker`);
- while it is tracked, each frame hands the tracker that object alone: the detection of its kind
  nearest where the tracker believes it (within ``gate``), or, when none is, an OCCLUDED
  refusal, so the tracker's own rules for a hidden or held object apply and the other objects
  never count as "another object" to it;
- once the tracked object stands in the drop area and the hand has left it (``done_clearance``),
  or when the cell's sequencer says so (:meth:`SceneTargetTracker.next_object`: the detector node's
  ``~next``), it is done: the tracker forgets it and the next one is chosen. Switching while the
  policy still lets go of it sent the hand to the next object through the one just placed.

The other objects stay where they are: nothing is published about them here (the node's
``~objects`` report carries them all). Pure numpy, fed by the node.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from ..clearing import ClearingSettings, KINDS, check_rule, choose_next
from .detector import Refusal, RefusalReason
from .scene_detector import SceneDetection, SceneObjectFound
from .scene_tracker import SceneTracker
from .tracker import ObjectTracker, TrackedObject, TrackState


@dataclass(frozen=True)
class Selection:
    """How the next object is chosen.

    :param rule: ``nearest`` | ``kind`` | ``id`` (:data:`fr5_rl.clearing.RULES`).
    :param kind: rule ``kind``: only this kind (``cylinder``, ``square box``, ``rectangular
        box``); "" : the clearing settings' ``kind_order``.
    :param track_id: rule ``id``: the object's track id (``fr5_rl/DetectedObjects``).
    """

    rule: str = "nearest"
    kind: str = ""
    track_id: int = 0

    def check(self) -> None:
        """:raises ValueError: a rule, kind or id that cannot choose anything (the message says which)."""
        check_rule(self.rule)
        if self.kind and self.kind not in KINDS:
            raise ValueError(f"kind {self.kind!r} is none of {', '.join(KINDS)}")
        if self.rule == "id" and self.track_id < 1:
            raise ValueError("rule 'id' needs the object's track id (1, 2, ...: fr5_rl/DetectedObjects id)")


@dataclass(frozen=True)
class SceneFrame:
    """What one frame gave.

    :param target: the chosen object's pose to publish (:class:`TrackedObject`), or why not.
    :param objects: ``(id, object)`` of every object the frame shows whole.
    :param chosen_id: the target's track id (0: none chosen).
    """

    target: Union[TrackedObject, Refusal]
    objects: List[Tuple[int, SceneObjectFound]]
    chosen_id: int


class SceneTargetTracker:
    """Chooses the next object of a scene and follows it through the one-object tracker.

    :param tracker: the one-object tracker whose answer is the policy's target.
    :param scene_tracker: the track ids of every object.
    :param clearing: the drop area (placed objects) and the rule's reference point and kind order.
    :param gate: m in the table plane: the detection of the tracked object's kind nearest where it
        is believed, this near, is it.
    :param selection: the first rule.
    :param reacquire_timeout: s: an object the tracker lost outside the drop area (the arm hid it
        too long) is looked for where it was this long, then the rule chooses anew.
    :param done_clearance: m: an object set down in the drop area is done once the tcp is this far
        from it (a policy letting go of it still needs it as its target), or when the cell's
        sequencer says so (:meth:`next_object`).
    """

    def __init__(self, tracker: ObjectTracker, scene_tracker: SceneTracker, clearing: ClearingSettings,
                 gate: float, selection: Selection = Selection(), done_clearance: float = 0.12,
                 reacquire_timeout: float = 10.0) -> None:
        selection.check()
        self.tracker, self.scene_tracker, self.clearing, self.gate = tracker, scene_tracker, clearing, gate
        self.selection, self.done_clearance, self.reacquire_timeout = selection, done_clearance, reacquire_timeout
        self.pending_since: Optional[float] = None  # when a lost object began to be looked for again (s)
        self.last_objects: List[Tuple[int, SceneObjectFound]] = []  # the last frame's, with their ids
        self.pending: Optional[Tuple[float, float, float]] = None  # chosen by next_object(), not yet followed
        self.set_down: Optional[Tuple[float, float, float]] = None  # lost under the hand in the drop area
        self.chosen_id = 0
        self.chosen_kind = ""
        self.position: Optional[Tuple[float, float, float]] = None  # where the tracker believes it (m, table)

    def select(self, selection: Selection) -> str:
        """Choose by ``selection`` from now on: at once, unless the target is in the hand (then
        from the next choice, once it has been set down). The selection in force changes nothing.

        :raises ValueError: ``selection`` cannot choose anything.
        :return: what happens, for a person.
        """
        selection.check()
        if selection == self.selection:
            return f"{selection.rule}: unchanged"
        self.selection = selection
        if self.tracker.state is TrackState.IN_HAND:
            return f"{selection.rule}: from the next object (object {self.chosen_id} is in the hand)"
        self._forget()
        return f"{selection.rule}: choosing now"

    def next_object(self) -> Optional[Tuple[int, SceneObjectFound]]:
        """The cell's sequencer says the current object is done (placed, or given up): forget it
        and choose the next one now, among the objects of the last frame.

        :return: ``(id, object)`` of the object chosen (the next frames follow it), or None when
            the last frame showed none to choose (then each frame chooses by the rule).
        """
        self._forget()
        choice = self._choose(self.last_objects)
        if isinstance(choice, Refusal):
            return None
        self.chosen_id, self.chosen_kind = choice[0], choice[1].detection.kind
        self.pending = tuple(choice[1].detection.position_table)
        return choice

    def update(self, scene: SceneDetection, stamp: float, depth: Optional[np.ndarray] = None, intrinsics=None,
               table_from_optical: Optional[np.ndarray] = None, table_from_tcp: Optional[np.ndarray] = None,
               gripper_width: Optional[float] = None, commanded_width: Optional[float] = None) -> SceneFrame:
        """One frame: the scene's ids, the choice, and the tracker's answer for the chosen object.

        :param scene: the frame's objects (:func:`~fr5_rl.perception.scene_detector.detect_scene`).
        :param stamp: its capture time (s). The rest as :meth:`ObjectTracker.update` takes them.
        """
        objects = self.last_objects = self.scene_tracker.update(scene, stamp)
        if self.set_down is not None:
            if not self._hand_away(self.set_down, table_from_tcp):
                return SceneFrame(Refusal(RefusalReason.NO_OBJECT, "the object set down in the drop area is lost "
                                                                   "to the camera: waiting for the hand to leave it "
                                                                   "(or ~next)"), objects, 0)
            self.set_down = None
        match: Optional[Tuple[int, SceneObjectFound]] = None
        state = self.tracker.state
        if state is not TrackState.LOST and self.position is not None:
            match = self._nearest(objects, self.chosen_kind, self.position)
            where = match[1].detection.position_table if match is not None else self.position
            if state is not TrackState.IN_HAND and self.clearing.in_drop_area(where[:2]) \
                    and self._hand_away(where, table_from_tcp):
                self._forget()  # set down in the drop area, and the hand has left it: done
                match = None
        if self.pending is not None and self.pending_since is not None \
                and stamp - self.pending_since > self.reacquire_timeout:
            self._forget()  # lost, and not seen where it was for that long: gone
        if self.tracker.state is TrackState.LOST and self.pending is not None:
            # Chosen by next_object(), or lost on the way: that object, once a frame shows it.
            match = self._nearest(objects, self.chosen_kind, self.pending)
            if match is None:
                return SceneFrame(Refusal(RefusalReason.OCCLUDED, f"object {self.chosen_id} ({self.chosen_kind}) "
                                                                  f"not seen whole where it was"), objects, self.chosen_id)
            self.pending = None
        elif self.tracker.state is TrackState.LOST:
            self.chosen_id, self.chosen_kind = 0, ""
            choice = self._choose(objects)
            if isinstance(choice, Refusal):
                return SceneFrame(choice, objects, 0)
            match = choice
            self.chosen_id, self.chosen_kind = match[0], match[1].detection.kind
        if match is not None:
            self.chosen_id = match[0]  # the scene tracker may have given it a new id (in the hand, it moved far)
            fed = match[1].detection
        else:
            fed = Refusal(RefusalReason.OCCLUDED, f"object {self.chosen_id} ({self.chosen_kind}) not seen whole")
        target = self.tracker.update(fed, stamp, depth, intrinsics, table_from_optical, table_from_tcp,
                                     gripper_width, commanded_width)
        if isinstance(target, TrackedObject):
            self.position = target.position_table
        elif self.tracker.state is TrackState.LOST:
            lost_at, lost_id, lost_kind = self.position, self.chosen_id, self.chosen_kind
            self._forget()
            if lost_at is not None and self.clearing.in_drop_area(lost_at[:2]):
                if not self._hand_away(lost_at, table_from_tcp):
                    # Lost where it was set down, under the hand (which hides it): not a reason to send
                    # the hand to the next object while the policy may still be letting go of this one.
                    self.set_down = tuple(lost_at)
            elif lost_at is not None:
                # Lost on the way (the arm hid it longer than the tracker's hidden_timeout): the same
                # object where it was, once a frame shows it, not the rule's next one. Choosing anew
                # sent the hand to another object than the one the cell had named (stop 66).
                self.chosen_id, self.chosen_kind = lost_id, lost_kind
                self.pending, self.pending_since = tuple(lost_at), stamp
        return SceneFrame(target, objects, self.chosen_id)

    def _hand_away(self, position: Sequence[float], table_from_tcp: Optional[np.ndarray]) -> bool:
        """Whether the tcp is more than ``done_clearance`` from ``position`` (m, table frame):
        a policy still letting go of a placed object needs it as its target (unknown: away)."""
        if table_from_tcp is None:
            return True
        tcp = np.asarray(table_from_tcp, dtype=np.float64)[:3, 3]
        return float(np.linalg.norm(tcp - np.asarray(position, dtype=np.float64))) > self.done_clearance

    # ------------------------------------------------------------------ inside
    def _forget(self) -> None:
        self.tracker.reset()
        self.chosen_id, self.chosen_kind, self.position, self.pending = 0, "", None, None
        self.set_down, self.pending_since = None, None

    def _choose(self, objects: Sequence[Tuple[int, SceneObjectFound]]
                ) -> Union[Tuple[int, SceneObjectFound], Refusal]:
        pickable = [entry for entry in objects
                    if not self.clearing.in_drop_area(entry[1].detection.position_table[:2])]
        selection = self.selection
        if selection.rule == "id":
            chosen = next((entry for entry in pickable if entry[0] == selection.track_id), None)
            if chosen is None:
                return Refusal(RefusalReason.NO_OBJECT, f"object {selection.track_id} is not in view outside "
                                                        f"the drop area (rule id)")
            return chosen
        chosen = choose_next([(entry, entry[1].label, entry[1].detection.position_table[:2]) for entry in pickable],
                             selection.rule, self.clearing.reference_xy, self.clearing.kind_order,
                             selection.kind or None)
        if chosen is None:
            what = f"no {selection.kind}" if selection.kind else "no object"
            return Refusal(RefusalReason.NO_OBJECT, f"{what} in view outside the drop area (rule {selection.rule}): the table is clear, or the arm hides what is left")
        return chosen

    def _nearest(self, objects: Sequence[Tuple[int, SceneObjectFound]], kind: str,
                 position: Sequence[float]) -> Optional[Tuple[int, SceneObjectFound]]:
        best, best_distance = None, self.gate
        for entry in objects:
            xyz = entry[1].detection.position_table
            distance = math.hypot(xyz[0] - position[0], xyz[1] - position[1])
            if entry[1].detection.kind == kind and distance <= best_distance:
                best, best_distance = entry, distance
        return best
