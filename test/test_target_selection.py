"""Clearing the table: the rule that picks the next object (fr5_rl.clearing), and the detector's
selection that follows one object of a scene into the hand and out of it
(fr5_rl.perception.target_selection). Detections are built by hand: what is tested is the choice
and the hand-over to the one-object tracker, not the measurement."""
import dataclasses
import math

import numpy as np
import pytest

from fr5_rl.clearing import ClearingSettings, choose_next
from fr5_rl.config import ConfigError, load_yaml, typed
from fr5_rl.env_config import load_env_config
from fr5_rl.perception.detector import Detection, DetectorSettings, Refusal, RefusalReason, TableRegion
from fr5_rl.perception.scene_detector import SceneDetection, SceneObjectFound
from fr5_rl.perception.scene_tracker import SceneTracker
from fr5_rl.perception.target_selection import SceneTargetTracker, Selection
from fr5_rl.perception.tracker import ObjectTracker, TrackedObject, TrackerSettings, TrackState
from fr5_rl.transforms import matrix_from_xyz_rpy

CLEARING = ClearingSettings.from_yaml()
# The selection's tests name positions by their distance to the robot's base.
AT_BASE = dataclasses.replace(CLEARING, reference_xy=[0.0, 0.0])


# ----------------------------------------------------------------------------- the rule
def test_nearest_is_nearest_to_the_reference_point():
    candidates = [("far", "cylinder", (-0.65, 0.0)), ("near", "square box", (-0.40, -0.20)),
                  ("middle", "cylinder", (-0.50, 0.05))]
    assert choose_next(candidates, "nearest", (0.0, 0.0)) == "near"
    assert choose_next(candidates, "nearest", (-0.66, 0.0)) == "far"
    assert choose_next([], "nearest", (0.0, 0.0)) is None


def test_kind_takes_the_kinds_in_order_then_the_nearest_of_that_kind():
    candidates = [("box", "square box", (-0.40, 0.0)), ("far cylinder", "cylinder", (-0.65, 0.0)),
                  ("near cylinder", "cylinder", (-0.50, 0.0))]
    assert choose_next(candidates, "kind", (0.0, 0.0), ["cylinder", "square box"]) == "near cylinder"
    assert choose_next(candidates, "kind", (0.0, 0.0), ["rectangular box", "square box"]) == "box"
    assert choose_next(candidates, "kind", (0.0, 0.0), wanted_kind="rectangular box") is None
    # A kind the order does not name still comes, after those it names.
    assert choose_next(candidates[:1], "kind", (0.0, 0.0), ["cylinder"]) == "box"


def test_a_rule_that_names_nothing_is_refused():
    with pytest.raises(ConfigError, match="farthest"):
        choose_next([], "farthest", (0.0, 0.0))
    with pytest.raises(ValueError, match="id"):
        choose_next([], "id", (0.0, 0.0))


@pytest.mark.parametrize("change, message", [
    ({"drop_area_low": [-0.72, -0.05]}, "overlap"),
    ({"drop_slots": [[-0.5, -0.1, 0.0]]}, "drop_slots"),
    ({"rule": "farthest"}, "farthest"),
    ({"kind_order": ["sphere"]}, "sphere"),
    ({"count": [3, 9]}, "count"),
])
def test_clearing_settings_that_cannot_work_are_refused(change, message):
    data = {**load_yaml("clearing"), **change}
    with pytest.raises(ConfigError, match=message):
        typed(ClearingSettings, data, "clearing.yaml")


def test_the_drop_slots_lie_in_the_placement_region_the_policy_was_trained_on():
    region = load_env_config().object
    for x, y, _ in CLEARING.drop_slots:
        assert region.region_low[0] <= x <= region.region_high[0] and region.region_low[1] <= y <= region.region_high[1]
    assert region.region_low[0] <= CLEARING.pick_area_low[0] and CLEARING.pick_area_high[1] <= region.region_high[1]


# ----------------------------------------------------------------------------- the selection
HEIGHT = 0.06


def found(x: float, y: float, kind: str = "cylinder", size: float = 0.05) -> SceneObjectFound:
    """An object standing at (x, y) (m, table frame) as the scene detector reports it."""
    detection = Detection((0.0, 0.0, 1.0), (x, y, HEIGHT / 2.0), HEIGHT, (0.0, 0.0), 10.0, 100, size, kind, 0.0,
                          (size, size))
    return SceneObjectFound(detection, "cylinder" if kind == "cylinder" else "square box")


class Cell:
    """A selection fed frame after frame (no depth: the tracker keeps a hidden object as it is)."""

    def __init__(self, selection=None):
        table = TableRegion.from_env(load_env_config())
        settings = TrackerSettings.from_yaml()
        self.tracker = ObjectTracker(settings, typed(DetectorSettings, load_yaml("detector")["detector"], "d"), table)
        self.selector = SceneTargetTracker(self.tracker, SceneTracker(0.02, settings.hidden_timeout), AT_BASE, 0.04,
                                           selection or Selection())
        self.stamp = 0.0

    def frame(self, *objects, tcp=None, width=None, commanded=None):
        self.stamp += 0.1
        return self.selector.update(SceneDetection(tuple(objects), ()), self.stamp, table_from_tcp=tcp,
                                    gripper_width=width, commanded_width=commanded)

    def between(self, tcp, width, commanded=None):
        self.stamp += 0.02
        return self.tracker.hand_between_frames(self.stamp, tcp, width, commanded)


def tcp_at(x: float, y: float, z: float) -> np.ndarray:
    return matrix_from_xyz_rpy([x, y, z], [math.pi, 0.0, 0.0])


def chosen_position(frame):
    assert isinstance(frame.target, TrackedObject), frame.target
    return frame.target.position_table[:2]


def test_the_nearest_object_is_chosen_and_kept_while_others_come_and_go():
    cell = Cell()
    first = cell.frame(found(-0.60, -0.20), found(-0.42, -0.10), found(-0.55, 0.0, "box"))
    assert chosen_position(first) == pytest.approx((-0.42, -0.10))
    assert first.chosen_id == dict((obj.detection.position_table[:2], i) for i, obj in first.objects)[(-0.42, -0.10)]
    # A nearer one put down meanwhile does not take over the object being picked.
    later = cell.frame(found(-0.60, -0.20), found(-0.42, -0.10), found(-0.37, -0.05))
    assert chosen_position(later) == pytest.approx((-0.42, -0.10)) and later.chosen_id == first.chosen_id
    # Not in this frame (hidden): the tracker is told it is hidden, never handed another object.
    hidden = cell.frame(found(-0.60, -0.20), found(-0.37, -0.05))
    assert isinstance(hidden.target, Refusal) and hidden.target.reason is RefusalReason.OCCLUDED
    assert hidden.chosen_id == first.chosen_id and cell.tracker.state is TrackState.SEEN
    again = cell.frame(found(-0.60, -0.20), found(-0.42, -0.10), found(-0.37, -0.05))
    assert chosen_position(again) == pytest.approx((-0.42, -0.10)) and again.chosen_id == first.chosen_id


def test_objects_in_the_drop_area_are_never_chosen():
    cell = Cell()
    placed = found(*CLEARING.drop_slots[2][:2])  # nearer the base than the other
    frame = cell.frame(placed, found(-0.65, -0.25))
    assert chosen_position(frame) == pytest.approx((-0.65, -0.25))
    cell = Cell()
    frame = cell.frame(placed)
    assert isinstance(frame.target, Refusal) and frame.target.reason is RefusalReason.NO_OBJECT
    assert frame.chosen_id == 0 and "drop area" in frame.target.detail


def test_the_object_carried_to_the_drop_area_is_done_and_the_next_one_is_chosen():
    cell = Cell()
    picked, other = found(-0.42, -0.10), found(-0.62, -0.20)
    first = cell.frame(picked, other)
    assert chosen_position(first) == pytest.approx((-0.42, -0.10))
    # The fingers close on it and lift it: in the hand.
    size = picked.detection.size
    assert cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0), size, 0.0) is None
    held = cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0 + 0.03), size, 0.0)
    assert held is not None and held.state is TrackState.IN_HAND
    # Carried over the table: the other object stays where it is and is never the target.
    goal = CLEARING.drop_slots[0][:2]
    carried = cell.frame(other, tcp=tcp_at(goal[0], goal[1], HEIGHT / 2.0 + 0.05), width=size, commanded=0.0)
    assert carried.target.state is TrackState.IN_HAND and chosen_position(carried) == pytest.approx(goal, abs=0.01)
    # Set down and let go: seen standing at the goal, it is done; the other one is next.
    down = tcp_at(goal[0], goal[1], HEIGHT / 2.0)
    let_go = cell.frame(other, tcp=down, width=0.08, commanded=0.08)
    assert let_go.target.state is TrackState.HIDDEN
    # The hand still over it (the policy lets go and rises): it stays the target.
    still = cell.frame(found(*goal), other, tcp=tcp_at(goal[0], goal[1], HEIGHT + 0.03), width=0.08, commanded=0.08)
    assert chosen_position(still) == pytest.approx(goal, abs=0.01)
    # The hand gone from it: done, and the other one is next.
    away = tcp_at(goal[0], goal[1] - 0.1, HEIGHT + 0.15)
    next_one = cell.frame(found(*goal), other, tcp=away, width=0.08, commanded=0.08)
    assert chosen_position(next_one) == pytest.approx((-0.62, -0.20))


def test_an_object_lost_under_the_hand_in_the_drop_area_sends_the_hand_nowhere_else():
    cell = Cell()
    picked, other = found(-0.42, -0.10), found(-0.62, -0.20)
    cell.frame(picked, other)
    size = picked.detection.size
    cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0), size, 0.0)
    assert cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0 + 0.03), size, 0.0).state is TrackState.IN_HAND
    goal = CLEARING.drop_slots[0][:2]
    hover = tcp_at(goal[0], goal[1], HEIGHT + 0.07)  # let go, and hovering over it: it hides the object
    assert cell.frame(other, tcp=hover, width=0.08, commanded=0.08).target.state is TrackState.HIDDEN
    cell.stamp += TrackerSettings.from_yaml().hidden_timeout  # hidden too long: the tracker drops it
    for _ in range(3):
        held = cell.frame(other, tcp=hover, width=0.08, commanded=0.08)
        assert isinstance(held.target, Refusal) and held.chosen_id == 0, held
    # The hand gone: the next object.
    away = tcp_at(goal[0], goal[1] - 0.1, HEIGHT + 0.2)
    assert chosen_position(cell.frame(other, tcp=away, width=0.08, commanded=0.08)) == pytest.approx((-0.62, -0.20))


def test_an_object_hidden_too_long_is_looked_for_where_it_was_not_swapped_for_another():
    cell = Cell()
    chosen, other = found(-0.42, -0.10), found(-0.62, -0.20)
    first = cell.frame(chosen, other)
    assert chosen_position(first) == pytest.approx((-0.42, -0.10))
    hidden_timeout = TrackerSettings.from_yaml().hidden_timeout
    cell.stamp += hidden_timeout  # the arm hides it longer than the tracker waits
    for _ in range(3):
        lost = cell.frame(other)
        assert isinstance(lost.target, Refusal) and lost.chosen_id == first.chosen_id, lost
    # Seen again: the same object, not the other one.
    again = cell.frame(chosen, other)
    assert chosen_position(again) == pytest.approx((-0.42, -0.10))
    # Gone for good: after reacquire_timeout the rule chooses anew.
    cell.stamp += hidden_timeout
    cell.frame(other)
    cell.stamp += cell.selector.reacquire_timeout
    cell.frame(other)
    assert chosen_position(cell.frame(other)) == pytest.approx((-0.62, -0.20))


def test_the_cells_next_chooses_at_once_and_that_object_is_followed():
    cell = Cell()
    first, second, third = found(-0.40, -0.10), found(-0.50, -0.15), found(-0.65, -0.25)
    assert chosen_position(cell.frame(first, second, third)) == pytest.approx((-0.40, -0.10))
    chosen = cell.selector.next_object()  # given up on the first: it stays, but is no longer chosen ...
    assert chosen is not None and chosen[1].detection.position_table[:2] == (-0.40, -0.10)
    # ... unless the rule names it again: the rule's choice among the last frame's objects.
    cell.selector.select(Selection("kind", "square box"))
    box = found(-0.60, 0.0, "box")
    cell.frame(first, second, box)
    chosen = cell.selector.next_object()
    assert chosen[1].detection.position_table[:2] == (-0.60, 0.0) and cell.selector.chosen_id == chosen[0]
    # The frames then follow that object, even when a nearer one of its kind comes.
    later = cell.frame(first, second, box, found(-0.36, -0.02, "box"))
    assert chosen_position(later) == pytest.approx((-0.60, 0.0)) and later.chosen_id == chosen[0]
    # Nothing left to choose: None, and every frame says so.
    cell = Cell()
    cell.frame(found(*CLEARING.drop_slots[0][:2]))
    assert cell.selector.next_object() is None


def test_a_rule_changed_while_an_object_is_in_the_hand_applies_to_the_next_choice():
    cell = Cell()
    picked, box = found(-0.42, -0.10), found(-0.62, -0.20, "box")
    cell.frame(picked, box)
    size = picked.detection.size
    cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0), size, 0.0)
    assert cell.between(tcp_at(-0.42, -0.10, HEIGHT / 2.0 + 0.03), size, 0.0).state is TrackState.IN_HAND
    answer = cell.selector.select(Selection("kind", "square box"))
    assert "next" in answer and cell.tracker.state is TrackState.IN_HAND
    # Not in the hand: at once; the rule in force again changes nothing.
    cell = Cell()
    cell.frame(picked, box)
    assert "unchanged" in cell.selector.select(Selection()) and cell.tracker.state is TrackState.SEEN
    assert "now" in cell.selector.select(Selection("kind", "square box"))
    assert chosen_position(cell.frame(picked, box)) == pytest.approx((-0.62, -0.20))


def test_rule_id_takes_that_object_or_says_it_is_not_there():
    cell = Cell()
    objects = cell.frame(found(-0.42, -0.10), found(-0.62, -0.20)).objects
    far_id = next(i for i, obj in objects if obj.detection.position_table[0] == -0.62)
    cell.selector.select(Selection("id", track_id=far_id))
    assert chosen_position(cell.frame(found(-0.42, -0.10), found(-0.62, -0.20))) == pytest.approx((-0.62, -0.20))
    cell.selector.select(Selection("id", track_id=far_id + 10))
    missing = cell.frame(found(-0.42, -0.10), found(-0.62, -0.20))
    assert isinstance(missing.target, Refusal) and str(far_id + 10) in missing.target.detail


@pytest.mark.parametrize("selection, message", [
    (Selection("farthest"), "farthest"), (Selection("kind", "sphere"), "sphere"), (Selection("id"), "id"),
])
def test_a_selection_that_cannot_choose_is_refused(selection, message):
    cell = Cell()
    with pytest.raises(ValueError, match=message):
        cell.selector.select(selection)
    assert cell.selector.selection == Selection()  # the one before stands

