"""The detector's algorithm and its input checks, on synthetic depth images (no ROS, no pybullet).

The scene: a camera 1 m above the table looking straight down; boxes are drawn as the depth of
their top faces (what such a camera sees of them). Settings: config/detector.yaml's."""
import math
import dataclasses

import numpy as np
import pytest

from fr5_rl.config import ConfigError
from fr5_rl.perception.camera_model import Intrinsics
from fr5_rl.perception.detector import (Detection, DetectorSettings, ObjectDetector, Refusal, RefusalReason,
                                        TableRegion)
from fr5_rl.perception.images import (InputError, check_frame, decode_color, decode_depth,
                                      intrinsics_from_camera_info)
from fr5_rl.perception.morphology import label_components
from fr5_rl.perception.overlay import draw_detection
from fr5_rl.perception.tracker import ObjectTracker, TrackedObject, TrackerSettings, TrackState, footprint_view
from fr5_rl.transforms import matrix_from_xyz_rpy

K = Intrinsics(640, 480, 615.0, 615.0, 322.0, 238.0)
# Optical frame 1 m above the table origin, z down, x along table +x, y along table -y.
TABLE_FROM_OPTICAL = matrix_from_xyz_rpy([0.0, 0.0, 1.0], [np.pi, 0.0, 0.0])
SETTINGS = DetectorSettings.from_yaml()
TABLE = TableRegion(region_low=(-0.3, -0.3), region_high=(0.3, 0.3), table_height=0.0)


def scene(*boxes):
    """Depth (m) of the table with boxes (cx, cy, half_x, half_y, height) seen from above."""
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    x, y = K.ray(u, v)
    depth = np.ones((K.height, K.width), dtype=np.float32)
    for cx, cy, hx, hy, height in boxes:
        z = 1.0 - height
        tx, ty = x * z, -(y * z)  # the top face's plane, in table coordinates
        inside = (np.abs(tx - cx) <= hx) & (np.abs(ty - cy) <= hy)
        depth[inside] = np.minimum(depth[inside], z)
    return depth


def detect(depth, settings=SETTINGS):
    return ObjectDetector(settings, TABLE).detect(depth, K, TABLE_FROM_OPTICAL)


def test_one_object_gives_its_centre():
    found = detect(scene((0.1, -0.05, 0.025, 0.025, 0.06)))
    assert isinstance(found, Detection), found
    np.testing.assert_allclose(found.position_table, (0.1, -0.05, 0.03), atol=1.5e-3)
    # The optical-frame position is the same point.
    back = TABLE_FROM_OPTICAL @ np.array([*found.position, 1.0])
    np.testing.assert_allclose(back[:3], found.position_table, atol=1e-9)
    assert found.top_height == pytest.approx(0.06, abs=1e-3)


def test_known_object_height_places_the_centre_below_the_top():
    lifted = scene((0.0, 0.0, 0.025, 0.025, 0.08))  # top 8 cm up: a 6 cm object lifted 2 cm
    found = detect(lifted, dataclasses.replace(SETTINGS, object_height=0.06))
    assert found.position_table[2] == pytest.approx(0.05, abs=1e-3)


@pytest.mark.parametrize("depth, reason", [
    (scene(), RefusalReason.NO_OBJECT),
    (scene((0.1, 0.1, 0.02, 0.02, 0.05), (-0.1, -0.1, 0.02, 0.02, 0.05)), RefusalReason.SEVERAL_OBJECTS),
    (scene((0.5, 0.5, 0.02, 0.02, 0.05)), RefusalReason.NO_OBJECT),          # outside the region
    (scene((0.0, 0.0, 0.003, 0.003, 0.05)), RefusalReason.NO_OBJECT),        # too small to be it
    (scene((0.0, 0.0, 0.15, 0.15, 0.05)), RefusalReason.NO_OBJECT),          # too large
    # The gripper (higher than any object) over part of the object: hidden, not half a centre.
    (scene((0.0, 0.0, 0.025, 0.025, 0.06), (0.03, 0.0, 0.02, 0.04, 0.2)), RefusalReason.OCCLUDED),
    # A finger going down next to the object, continuous with the robot above: not an object.
    (scene((0.0, 0.0, 0.01, 0.01, 0.3), (0.0, 0.0, 0.02, 0.02, 0.07)), RefusalReason.OCCLUDED),
])
def test_holds_on_no_or_several_or_hidden_objects(depth, reason):
    found = detect(depth)
    assert isinstance(found, Refusal) and found.reason is reason, found


def test_a_robot_part_far_from_the_object_does_not_matter():
    found = detect(scene((0.1, 0.0, 0.025, 0.025, 0.06), (-0.15, 0.0, 0.03, 0.03, 0.4)))
    assert isinstance(found, Detection), found
    assert found.position_table[0] == pytest.approx(0.1, abs=1.5e-3)


def test_debug_image_draws_detection_and_refusal():
    color = np.zeros((K.height, K.width, 3), dtype=np.uint8)
    found = detect(scene((0.0, 0.0, 0.025, 0.025, 0.06)))
    drawn = draw_detection(color, found)
    assert (drawn[..., 1] == 255).any() and color.max() == 0
    refused = draw_detection(color, Refusal(RefusalReason.NO_OBJECT))
    assert (refused[0, :, 0] == 255).all()


# ----------------------------------------------------------------------------- tracking
OBJECT = (0.1, -0.05, 0.025, 0.025, 0.06)      # a 5 cm square, 6 cm high
GRIPPER_OVER_IT = (0.1, -0.05, 0.045, 0.045, 0.2)  # the gripper above it hides it whole


def tcp_at(x, y, z):
    pose = np.eye(4)
    pose[:3, 3] = (x, y, z)
    return pose


class Frames:
    """Feeds synthetic frames to a detector and a tracker, one stamp after the other."""

    def __init__(self, **settings):
        """:param settings: config/detector.yaml's tracker settings to change."""
        self.tracker = ObjectTracker(dataclasses.replace(TrackerSettings.from_yaml(), **settings), SETTINGS, TABLE)
        self.stamp = 0.0

    def __call__(self, depth, tcp=None, width=None, dt=0.1, commanded=None):
        self.stamp += dt
        return self.tracker.update(detect(depth), self.stamp, depth, K, TABLE_FROM_OPTICAL, tcp, width, commanded)


def test_size_is_measured_from_the_top_face():
    found = detect(scene(OBJECT))
    assert found.size == pytest.approx(0.05 * 2 / np.sqrt(3), rel=0.05)  # a square's equivalent width


def test_a_hidden_object_keeps_its_last_position_for_a_bounded_time():
    frames = Frames(hidden_timeout=1.0)
    seen = frames(scene(OBJECT))
    assert isinstance(seen, TrackedObject) and seen.state is TrackState.SEEN and seen.detection is not None
    hidden = frames(scene(OBJECT, GRIPPER_OVER_IT))
    assert isinstance(hidden, TrackedObject) and hidden.state is TrackState.HIDDEN, hidden
    assert hidden.position_table == seen.position_table and hidden.last_seen == pytest.approx(0.1)
    # Part of it showing beside a finger (the detector refuses it as OCCLUDED): still hidden.
    finger = (0.1, -0.05, 0.01, 0.04, 0.2)
    assert detect(scene(OBJECT, finger)).reason is RefusalReason.OCCLUDED
    assert frames(scene(OBJECT, finger)).state is TrackState.HIDDEN
    late = frames(scene(OBJECT, GRIPPER_OVER_IT), dt=1.0)
    assert isinstance(late, Refusal) and "hidden_timeout" in late.detail
    # The track is gone: hidden again, nothing is published until it is seen.
    assert isinstance(frames(scene(OBJECT, GRIPPER_OVER_IT)), Refusal)
    assert frames(scene(OBJECT)).state is TrackState.SEEN


def test_part_of_a_tracked_object_is_not_taken_for_it():
    frames = Frames()
    seen = frames(scene(OBJECT))
    # Only its lower 4 cm show where it stands (a finger hides the top): the detector alone
    # takes that for an object, the tracker for a part of the one it knows.
    view = scene((0.1, -0.05, 0.025, 0.025, 0.04))
    assert isinstance(detect(view), Detection)
    part = frames(view)
    assert isinstance(part, TrackedObject) and part.state is TrackState.HIDDEN, part
    assert part.position_table == seen.position_table


def test_an_object_that_has_gone_is_not_tracked():
    frames = Frames()
    frames(scene(OBJECT))
    gone = frames(scene())  # bare table where it stood, nothing in front
    assert isinstance(gone, Refusal) and gone.reason is RefusalReason.NO_OBJECT and "bare" in gone.detail
    # Even with the gripper arriving later, the track stays dropped.
    assert isinstance(frames(scene(GRIPPER_OVER_IT)), Refusal)


def test_a_hidden_object_pushed_by_the_fingers_is_found_beside_its_old_place():
    pushed = (0.13, -0.05, 0.025, 0.025, 0.06)       # 3 cm along x: its old place shows bare table
    finger = (0.13, -0.05, 0.012, 0.045, 0.2)        # over its middle, so the detector refuses it
    view = scene(pushed, finger)
    assert detect(view).reason is RefusalReason.OCCLUDED
    frames = Frames()
    frames(scene(OBJECT))
    moved = frames(view)
    assert isinstance(moved, TrackedObject) and moved.state is TrackState.HIDDEN, moved
    assert moved.position_table[0] == pytest.approx(0.13, abs=0.006)
    assert moved.position_table[1] == pytest.approx(-0.05, abs=0.006)
    # Without the search (nudge_radius 0) the same frame drops the track, as before.
    frames = Frames(nudge_radius=0.0)
    frames(scene(OBJECT))
    assert isinstance(frames(view), Refusal)
    # Pushed further than nudge_radius: dropped.
    frames = Frames(nudge_radius=0.01)
    frames(scene(OBJECT))
    assert isinstance(frames(view), Refusal)


def test_the_robot_elsewhere_does_not_keep_a_gone_object():
    frames = Frames()
    frames(scene(OBJECT))
    gone = frames(scene((-0.15, 0.1, 0.03, 0.03, 0.4)))
    assert isinstance(gone, Refusal)


def test_two_candidates_hold_and_drop_the_track():
    frames = Frames()
    frames(scene(OBJECT))
    two = frames(scene(OBJECT, (-0.1, 0.1, 0.02, 0.02, 0.05)))
    assert isinstance(two, Refusal) and two.reason is RefusalReason.SEVERAL_OBJECTS
    assert isinstance(frames(scene(OBJECT, GRIPPER_OVER_IT)), Refusal)


def test_finger_tips_beside_a_tracked_object_are_not_another_one():
    tips = ((0.1, 0.0, 0.012, 0.012, 0.07), (0.1, -0.1, 0.012, 0.012, 0.07))  # lower than the robot's cut
    view = scene(OBJECT, *tips)
    untracked = detect(view)
    assert untracked.reason is RefusalReason.SEVERAL_OBJECTS and len(untracked.candidates) == 3
    frames = Frames()
    seen = frames(scene(OBJECT))
    # The object whole among the tips: it is seen, at its place.
    beside = frames(view)
    assert isinstance(beside, TrackedObject) and beside.state is TrackState.SEEN, beside
    np.testing.assert_allclose(beside.position_table, seen.position_table, atol=1e-6)
    # Its top hidden, only its lower part among the tips: hidden, not dropped.
    low_part = scene((0.1, -0.05, 0.025, 0.025, 0.04), *tips)
    assert detect(low_part).reason is RefusalReason.SEVERAL_OBJECTS
    hidden = frames(low_part)
    assert isinstance(hidden, TrackedObject) and hidden.state is TrackState.HIDDEN, hidden
    # A second object like it is not a tip: which is which cannot be told, the track goes.
    twin = frames(scene(OBJECT, (-0.1, 0.1, 0.025, 0.025, 0.06), *tips))
    assert isinstance(twin, Refusal) and twin.reason is RefusalReason.SEVERAL_OBJECTS
    assert frames.tracker.state is TrackState.LOST


def test_bad_frames_leave_the_track_alone():
    frames = Frames()
    frames(scene(OBJECT))
    refusal = Refusal(RefusalReason.STALE, "old")
    assert frames.tracker.update(refusal, 0.15) is refusal
    assert frames(scene(OBJECT, GRIPPER_OVER_IT)).state is TrackState.HIDDEN


def test_an_object_in_the_hand_moves_with_the_tcp():
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre = np.array(seen.position_table)
    size = seen.detection.size
    # The gripper comes down around it, open: hidden, in place.
    down = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp_at(*(centre + [0.0, 0.0, 0.01])), width=0.08)
    assert down.state is TrackState.HIDDEN and down.position_table == seen.position_table
    # The fingers close on it; while they are still closing the tcp may move: not yet taken.
    tcp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=size).state is TrackState.HIDDEN
    closed = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=size)
    assert closed.state is TrackState.IN_HAND
    np.testing.assert_allclose(closed.position_tcp, [0.0, 0.0, -0.01], atol=1e-9)  # published in the tcp frame
    # It rises with the tcp, unseen, past hidden_timeout.
    up = frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*(centre + [0.01, 0.0, 0.06])), width=size, dt=2.5)
    assert up.state is TrackState.IN_HAND
    np.testing.assert_allclose(up.position_table, centre + [0.01, 0.0, 0.05], atol=1e-9)
    # The fingers open high above the table: let go; where it was held, the table is bare.
    assert frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*(centre + [0.01, 0.0, 0.06])), width=0.08).state \
        is TrackState.HIDDEN
    dropped = frames(scene(), tcp=tcp_at(*(centre + [0.01, 0.0, 0.06])), width=0.08)
    assert isinstance(dropped, Refusal) and "bare" in dropped.detail


def test_frames_without_the_opening_or_the_tcp_keep_the_object_in_the_hand():
    """A gripper read back at 10 Hz leaves frames with no opening within 0.1 s (and tf may miss a
    frame): unknown is not let go. Taken for standing on the table, the object was dropped 2 s
    later while still in the hand, and the policy held until its episode ran out (the grasp
    rehearsal's timeouts). A frame that shows the fingers open still lets it go."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size)  # closing
    # A frame without the opening between the closing ones keeps the grasp pose.
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=None).state is TrackState.HIDDEN
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size).state is TrackState.IN_HAND
    lifted = centre + [0.0, 0.0, 0.06]
    for _ in range(25):  # 2.5 s of frames with no opening, longer than hidden_timeout
        up = frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*lifted), width=None)
        assert up.state is TrackState.IN_HAND, up
    np.testing.assert_allclose(up.position_table, centre + [0.0, 0.0, 0.05], atol=1e-9)
    # Nor does a frame without the tcp: the object stays where the hand last had it.
    still = frames(scene(GRIPPER_OVER_IT), tcp=None, width=size)
    assert still.state is TrackState.IN_HAND and still.position_table == up.position_table
    # The fingers open: let go.
    assert frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*lifted), width=0.08).state is TrackState.HIDDEN


def test_fingers_opened_wider_than_they_held_it_have_let_go():
    """A big object: fingers 71 mm open on a 69 mm cylinder were still "around it" by its top
    face's measured width plus grasp_width_margin; the tracker lifted it with the hand that had
    just set it down, and the policy never finished letting go. Opened release_opening wider
    than the narrowest they held it at, they have let go; squeezing on, they have not."""
    frames = Frames(release_opening=0.004)
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    held_at = size - 0.002
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=held_at)  # closing
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=held_at).state is TrackState.IN_HAND
    up = tcp_at(*(centre + [0.0, 0.0, 0.05]))
    assert frames(scene(GRIPPER_OVER_IT), tcp=up, width=held_at - 0.001).state is TrackState.IN_HAND  # squeezing
    # Set down, the fingers open 5 mm: still within its measured width plus the margin...
    opened = held_at - 0.001 + 0.005
    assert opened <= size + frames.tracker.settings.grasp_width_margin
    # ...but wider than they held it: let go, standing where the hand set it down.
    released = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=opened)
    assert released.state is TrackState.HIDDEN, released
    assert released.position_table[2] == pytest.approx(seen.position_table[2])


def test_a_grip_that_widens_while_told_to_close_still_holds():
    """An object caught near a pad's edge turns square between the pads after the lift: the
    fingers read 58 mm, then 64 mm on a 65 mm cylinder, all the while told to close (0 mm). By the
    widening alone that was a let-go: the tracker put the object back on the table under the
    lifted hand, and the policy, seeing it dropped, opened and grasped again until the time ran
    out (the rehearsal's place timeouts and knock-overs). Told to close, a grip that widens holds;
    told to open wider than it holds, and opened, it has let go."""
    frames = Frames(release_opening=0.004)
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08, commanded=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    caught_at = size - 0.009  # on a pad's edge: narrower than the object
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=caught_at, commanded=0.0)
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=caught_at,
                  commanded=0.0).state is TrackState.IN_HAND
    up = tcp_at(*(centre + [0.0, 0.0, 0.05]))
    squared = size - 0.001
    assert squared > caught_at + frames.tracker.settings.release_opening  # widened past the old rule
    still = frames(scene(GRIPPER_OVER_IT), tcp=up, width=squared, commanded=0.0)
    assert still.state is TrackState.IN_HAND, still
    # The command alone (the fingers not yet moved) lets nothing go...
    assert frames(scene(GRIPPER_OVER_IT), tcp=up, width=squared, commanded=0.08).state is TrackState.IN_HAND
    # ...the fingers opened by more than closing_tolerance past the grip they held do.
    opened = squared + frames.tracker.settings.closing_tolerance + 0.001
    released = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=opened, commanded=0.08)
    assert released.state is TrackState.HIDDEN, released


@pytest.mark.parametrize("with_command", [True, False])
def test_fingers_opening_off_a_set_down_object_do_not_take_it_back(with_command):
    """Set down and let go, the fingers open through widths that would hold the object while the
    hand rises off it: the rehearsal's tracker took that for a lift (the fingers "around it", the
    tcp lift_evidence above where they were) and carried the object up with the hand, 7 ms after
    the let-go. Told to open (or, the command unknown, opening from frame to frame), they are not
    around it: it stays standing where it was set down."""
    frames = Frames(release_opening=0.004)
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08, commanded=0.08 if with_command else None)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    held_at = size - 0.002
    close = 0.0 if with_command else None
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=held_at, commanded=close)
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=held_at, commanded=close).state is TrackState.IN_HAND
    opening = 0.08 if with_command else None
    released = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=held_at + 0.005, commanded=opening, dt=0.02)
    assert released.state is TrackState.HIDDEN, released
    # Still within a holding width, the hand already rising: not a lift.
    width = held_at + 0.005
    for rise in (0.005, 0.015, 0.03):
        width += 0.002
        assert width <= size + frames.tracker.settings.grasp_width_margin
        hand = tcp_at(*(centre + [0.0, 0.0, 0.01 + rise]))
        assert frames.tracker.hand_between_frames(frames.stamp, hand, width, opening) is None
        state = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=hand, width=width, commanded=opening, dt=0.02)
        assert state.state is TrackState.HIDDEN, (rise, state)
        assert state.position_table[2] == pytest.approx(seen.position_table[2])


def test_open_fingers_over_a_wide_object_are_not_on_it():
    """Fully open over an object within grasp_width_margin of the stroke (80 mm over a 70 mm
    cylinder), the fingers "fitted" it by their width, were not letting go (they were where they
    were told to be) and, not closing, counted as stopped on it: the first frame that hid the
    object took it into the hand (a hand rising 1 cm would too, between frames), and the object
    then moved with the tcp, 15 mm off where it stood when the fingers did close (the rehearsal,
    stop 64). Told to be open wider than the object, they are not on it; told to close, they take
    it as before."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08, commanded=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    open_width = size + 0.5 * frames.tracker.settings.grasp_width_margin  # "fits" by width alone
    low = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=low, width=open_width, commanded=open_width)
    for rise in (0.012, 0.02):
        hand = tcp_at(*(centre + [0.0, 0.0, 0.01 + rise]))
        assert frames.tracker.hand_between_frames(frames.stamp, hand, open_width, open_width) is None
        assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=hand, width=open_width, commanded=open_width,
                      dt=0.02).state is TrackState.HIDDEN
    # Told to close, the same fingers at the same width are on it: taken into the hand.
    closed = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=low, width=open_width, commanded=0.0, dt=0.02)
    assert closed.state is TrackState.IN_HAND


def test_without_the_command_a_widened_grip_has_let_go():
    """The same widening with the command unknown (no ~gripper_command_topic): the old rule."""
    frames = Frames(release_opening=0.004)
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    caught_at = size - 0.009
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=caught_at)
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=caught_at).state is TrackState.IN_HAND
    up = tcp_at(*(centre + [0.0, 0.0, 0.05]))
    assert frames(scene(GRIPPER_OVER_IT), tcp=up, width=size - 0.001).state is TrackState.HIDDEN


def test_a_tall_object_grasped_near_its_top_is_taken_into_the_hand():
    """A 10 cm object is grasped 2.5 cm below its top, its centre 4.5 cm below the tcp: farther
    than grasp_radius from the centre, but near the object. Measured from the centre, it was never
    taken, then dropped as hidden (the rehearsal's timeouts with the tall cylinders)."""
    tall = (0.1, -0.05, 0.02, 0.02, 0.10)
    frames = Frames()
    seen = frames(scene(tall), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.045]))
    assert np.linalg.norm(grasp[:3, 3] - centre) > frames.tracker.settings.grasp_radius
    frames(scene(tall, GRIPPER_OVER_IT), tcp=grasp, width=size)  # closing
    assert frames(scene(tall, GRIPPER_OVER_IT), tcp=grasp, width=size).state is TrackState.IN_HAND
    # Beside it by as much, at its centre's height: not near it.
    frames = Frames()
    frames(scene(tall), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    beside = tcp_at(*(centre + [0.045, 0.0, 0.0]))
    frames(scene(tall, GRIPPER_OVER_IT), tcp=beside, width=size)
    assert frames(scene(tall, GRIPPER_OVER_IT), tcp=beside, width=size).state is TrackState.HIDDEN


def test_an_object_lifted_before_the_fingers_show_stopped_is_in_the_hand():
    """A policy lifts as soon as the fingers close: by the frame that shows them stopped, the tcp
    can be 8 cm up and the table bare where the object stood. The fingers came around it in the
    frame before, so it is in the hand, at the offset it had then (not dropped as gone)."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=0.08).state is TrackState.HIDDEN  # open
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size).state is TrackState.HIDDEN  # closing
    lifted_tcp = centre + [0.0, 0.02, 0.09]
    lifted = frames(scene(), tcp=tcp_at(*lifted_tcp), width=size)
    assert isinstance(lifted, TrackedObject) and lifted.state is TrackState.IN_HAND, lifted
    np.testing.assert_allclose(lifted.position_tcp, [0.0, 0.0, -0.01], atol=1e-9)
    np.testing.assert_allclose(lifted.position_table, lifted_tcp + [0.0, 0.0, -0.01], atol=1e-9)

    # Opened past its width in between: whatever the fingers stop on later, far away, is not it.
    frames = Frames()
    frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size)
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=0.08)
    far = tcp_at(*(centre + [0.1, 0.0, 0.05]))
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=far, width=size)
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=far, width=size).state is TrackState.HIDDEN


def test_fingers_still_squeezing_while_the_arm_lifts_hold_the_object():
    """A fast gripper (the simulator's default driver) goes on closing by several mm a frame
    while the arm already lifts. Waiting for the fingers to stop left the object "hidden" on the
    table, and a policy that saw it left behind opened the hand (2026-11-28 vision runs). Risen
    ``lift_evidence`` above the lowest point where they were around it, at a width that holds it: in the hand."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size).state is TrackState.HIDDEN
    squeezing = size - 0.005  # closed 5 mm more than the frame before: still closing
    lifted_tcp = centre + [0.0, 0.0, 0.01 + 0.02]
    lifted = frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*lifted_tcp), width=squeezing)
    assert isinstance(lifted, TrackedObject) and lifted.state is TrackState.IN_HAND, lifted
    np.testing.assert_allclose(lifted.position_table, lifted_tcp + [0.0, 0.0, -0.01], atol=1e-9)
    # Squeezing without a lift is still closing: not yet in the hand.
    frames = Frames()
    frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size)
    still = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp_at(*(centre + [0.0, 0.0, 0.015])), width=size - 0.005)
    assert still.state is TrackState.HIDDEN
    # Off (lift_evidence larger than any lift): the old rule, hidden until the fingers stop.
    frames = Frames(lift_evidence=1.0)
    frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size)
    assert frames(scene(GRIPPER_OVER_IT), tcp=tcp_at(*lifted_tcp), width=squeezing).state is not TrackState.IN_HAND


def test_a_lift_in_the_fingers_is_seen_between_frames_from_the_tcp_and_the_fingers_alone():
    """The detector node checks the hand between frames (tf and the finger joints of now): a lift
    with the fingers around the object is IN_HAND at once, not a camera latency later. A frame
    captured before the fingers came around it (it arrives late) shows the object standing: that
    does not make the tracker forget the grasp."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)  # stamp 0.1
    centre, size = np.array(seen.position_table), seen.detection.size
    tracker = frames.tracker
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    assert tracker.hand_between_frames(0.12, grasp, 0.08) is None  # open: nothing between the fingers yet
    assert tracker.hand_between_frames(0.14, grasp, size) is None  # around it, not lifted
    # A late frame, captured at 0.13 (before the fingers closed), shows it standing.
    late = tracker.update(detect(scene(OBJECT)), 0.13, scene(OBJECT), K, TABLE_FROM_OPTICAL, grasp, 0.08)
    assert late.state is TrackState.SEEN
    lifted_tcp = centre + [0.0, 0.0, 0.01 + 0.015]
    held = tracker.hand_between_frames(0.16, tcp_at(*lifted_tcp), size - 0.004)
    assert held is not None and held.state is TrackState.IN_HAND
    np.testing.assert_allclose(held.position_tcp, [0.0, 0.0, -0.01], atol=1e-9)
    np.testing.assert_allclose(held.position_table, lifted_tcp + [0.0, 0.0, -0.01], atol=1e-9)
    # Unknown tcp or fingers, or nothing tracked: nothing changes.
    assert Frames().tracker.hand_between_frames(0.1, grasp, size) is None
    frames = Frames()
    frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    assert frames.tracker.hand_between_frames(0.12, None, size) is None
    assert frames.tracker.hand_between_frames(0.13, grasp, None) is None
    # Fingers closed on nothing (narrower than min_grasp_fraction of it) and lifted: not held.
    assert frames.tracker.hand_between_frames(0.14, grasp, 0.2 * size) is None
    assert frames.tracker.hand_between_frames(0.15, tcp_at(*lifted_tcp), 0.2 * size) is None


def test_a_remembered_grasp_pose_needs_this_frames_tcp_and_a_live_track():
    """The tcp pose with the fingers around the object is used only with this frame's tcp pose
    (tf may have none: the frame holds, no crash), and a reset or a sighting forgets it."""
    frames = Frames()
    seen = frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
    centre, size = np.array(seen.position_table), seen.detection.size
    grasp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    lifted = tcp_at(*(centre + [0.0, 0.02, 0.09]))

    def around_then(tcp, forget=None):
        frames = Frames()
        frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=0.08)
        frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=grasp, width=size + 0.005)  # closing around it
        if forget == "reset":
            frames.tracker.reset()
            frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=size)
        elif forget == "seen":
            frames(scene(OBJECT), tcp=tcp_at(0.1, -0.05, 0.3), width=size + 0.005)
        return frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=size + 0.004)  # stopped

    assert around_then(lifted).state is TrackState.IN_HAND
    assert around_then(None).state is TrackState.HIDDEN
    assert around_then(lifted, "reset").state is TrackState.HIDDEN
    assert around_then(lifted, "seen").state is TrackState.HIDDEN


def test_an_object_that_slipped_out_of_closed_fingers_is_not_followed():
    frames = Frames()
    seen = frames(scene(OBJECT))
    centre, size = np.array(seen.position_table), seen.detection.size
    tcp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    for _ in range(2):
        held = frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=size)
    assert held.state is TrackState.IN_HAND
    # Fingers still closed to its width, but where it should hang the camera sees the table.
    slipped = frames(scene(), tcp=tcp_at(*(centre + [0.0, 0.0, 0.08])), width=size)
    assert isinstance(slipped, Refusal) and "not in the hand" in slipped.detail


def test_the_tracker_says_its_state():
    frames = Frames()
    assert frames.tracker.state is TrackState.LOST
    seen = frames(scene(OBJECT))
    assert frames.tracker.state is TrackState.SEEN
    centre, size = np.array(seen.position_table), seen.detection.size
    tcp = tcp_at(*(centre + [0.0, 0.0, 0.01]))
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=0.08)
    assert frames.tracker.state is TrackState.HIDDEN
    for _ in range(2):
        frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=size)
    assert frames.tracker.state is TrackState.IN_HAND
    frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp, width=0.08)  # let go
    assert frames.tracker.state is TrackState.HIDDEN
    frames(scene())  # gone
    assert frames.tracker.state is TrackState.LOST


def test_fingers_closed_on_nothing_or_far_away_hold_nothing():
    frames = Frames()
    seen = frames(scene(OBJECT))
    centre = np.array(seen.position_table)
    # Closed all the way: it is not between the fingers.
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp_at(*centre), width=0.0).state is TrackState.HIDDEN
    # Closed to its width 10 cm away: not holding it.
    assert frames(scene(OBJECT, GRIPPER_OVER_IT), tcp=tcp_at(*(centre + [0.1, 0, 0])),
                  width=seen.detection.size).state is TrackState.HIDDEN


def test_footprint_view_tells_in_front_from_bare_table():
    found = detect(scene(OBJECT))
    args = (K, TABLE_FROM_OPTICAL, TABLE.table_height, SETTINGS.min_height, found.position_table, found.top_height,
            found.size, 0.01)
    assert footprint_view(scene(OBJECT), *args)[:2] == (0.0, 0.0)
    assert footprint_view(scene(OBJECT, GRIPPER_OVER_IT), *args)[:2] == (1.0, 0.0)
    assert footprint_view(scene(), *args)[:2] == (0.0, 1.0)


def test_debug_image_colours_say_where_the_position_comes_from():
    color = np.zeros((K.height, K.width, 3), dtype=np.uint8)
    frames = Frames()
    frames(scene(OBJECT))
    hidden = frames(scene(OBJECT, GRIPPER_OVER_IT))
    drawn = draw_detection(color, hidden, K, TABLE_FROM_OPTICAL)
    assert (drawn.reshape(-1, 3) == (255, 220, 0)).all(axis=1).any()


# ----------------------------------------------------------------------------- settings
def test_settings_come_from_the_yaml_sections_only(tmp_path):
    assert SETTINGS.min_height > 0 and TrackerSettings.from_yaml().hidden_timeout > 0
    path = tmp_path / "detector.yaml"
    path.write_text("detector: {min_height: 0.01}\ntracker: {}\n")
    with pytest.raises(ConfigError, match="missing key 'detector.region_margin'"):
        DetectorSettings.from_yaml(path)
    path.write_text("detector:\n" + "".join(f"  {f.name}: {getattr(SETTINGS, f.name)}\n"
                                             for f in dataclasses.fields(SETTINGS)) + "  min_heigth: 0.01\n")
    with pytest.raises(ConfigError, match="unknown key 'detector.min_heigth'"):
        DetectorSettings.from_yaml(path)
    with pytest.raises(ConfigError, match="must be a mapping"):
        TrackerSettings.from_yaml(path)  # no tracker section


# ----------------------------------------------------------------------------- components
def test_label_components_matches_a_flood_fill():
    rng = np.random.default_rng(3)
    mask = rng.random((40, 50)) > 0.6
    labels, count = label_components(mask)
    assert ((labels > 0) == mask).all()
    # Every 8-neighbour pair of set pixels shares a label, and the count is that of a flood fill.
    seen = np.zeros_like(mask)
    fills = 0
    for start in zip(*np.nonzero(mask)):
        if seen[start]:
            continue
        fills += 1
        stack = [start]
        seen[start] = True
        while stack:
            r, c = stack.pop()
            assert labels[r, c] == labels[start]
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    if 0 <= rr < 40 and 0 <= cc < 50 and mask[rr, cc] and not seen[rr, cc]:
                        seen[rr, cc] = True
                        stack.append((rr, cc))
    assert count == fills


# ----------------------------------------------------------------------------- bad input
def test_colour_decoding_and_unknown_encodings():
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    np.testing.assert_array_equal(decode_color("rgb8", 2, 3, 9, rgb.tobytes()), rgb)
    np.testing.assert_array_equal(decode_color("bgr8", 2, 3, 9, rgb[:, :, ::-1].tobytes()), rgb)
    padded = np.zeros((2, 12), dtype=np.uint8)  # rows padded to 12 bytes
    padded[:, :9] = rgb.reshape(2, 9)
    np.testing.assert_array_equal(decode_color("rgb8", 2, 3, 12, padded.tobytes()), rgb)
    with pytest.raises(InputError) as error:
        decode_color("yuv422", 2, 3, 6, bytes(12))
    assert error.value.refusal.reason is RefusalReason.ENCODING and "yuv422" in str(error.value)
    with pytest.raises(InputError) as error:
        decode_depth("8UC1", 2, 3, 3, bytes(6))
    assert error.value.refusal.reason is RefusalReason.ENCODING


def test_image_data_that_does_not_fit_its_size_is_refused():
    with pytest.raises(InputError) as error:
        decode_color("rgb8", 480, 640, 1920, bytes(100))
    assert error.value.refusal.reason is RefusalReason.BAD_IMAGE


def test_depth_decoding_millimetres_and_metres():
    mm = np.array([[0, 1000], [65535, 250]], dtype="<u2")
    np.testing.assert_allclose(decode_depth("16UC1", 2, 2, 4, mm.tobytes()), [[0, 1.0], [65.535, 0.25]])
    metres = np.array([[np.nan, 1.5], [np.inf, -1.0]], dtype="<f4")
    np.testing.assert_allclose(decode_depth("32FC1", 2, 2, 8, metres.tobytes()), [[0, 1.5], [0, 0]])
    big = np.array([[1000]], dtype=">u2")
    assert decode_depth("16UC1", 1, 1, 2, big.tobytes(), big_endian=True)[0, 0] == pytest.approx(1.0)


@pytest.mark.parametrize("k, p", [([0.0] * 9, [0.0] * 12), ([], []), ([615.0, 0, 320, 0, 0.0, 240, 0, 0, 1], [])])
def test_missing_or_zero_camera_info_is_refused(k, p):
    with pytest.raises(InputError) as error:
        intrinsics_from_camera_info(640, 480, k, p)
    assert error.value.refusal.reason is RefusalReason.CAMERA_INFO


def test_camera_info_uses_p_when_set():
    k = [600.0, 0, 320, 0, 600.0, 240, 0, 0, 1]
    p = [615.0, 0, 322.0, 0, 0, 616.0, 238.0, 0, 0, 0, 1, 0]
    assert intrinsics_from_camera_info(640, 480, k, p) == Intrinsics(640, 480, 615.0, 616.0, 322.0, 238.0)
    assert intrinsics_from_camera_info(640, 480, k, [0.0] * 12) == Intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)


def frame_check(color=None, depth=None, intrinsics=K, stamp=10.0, now=10.05):
    color = np.zeros((480, 640, 3), np.uint8) if color is None else color
    depth = np.ones((480, 640), np.float32) if depth is None else depth
    return check_frame(color, depth, intrinsics, stamp, now, timeout=0.3, min_valid_fraction=0.2)


def test_a_good_frame_passes_the_checks():
    assert frame_check() is None


@pytest.mark.parametrize("kwargs, reason", [
    (dict(depth=np.ones((240, 320), np.float32)), RefusalReason.SIZE_MISMATCH),
    (dict(color=np.zeros((480, 848, 3), np.uint8)), RefusalReason.SIZE_MISMATCH),
    (dict(intrinsics=Intrinsics(1280, 720, 900.0, 900.0, 640.0, 360.0)), RefusalReason.SIZE_MISMATCH),
    (dict(depth=np.zeros((480, 640), np.float32)), RefusalReason.DEPTH_INVALID),
    (dict(depth=decode_depth("32FC1", 480, 640, 2560, np.full((480, 640), np.nan, "<f4").tobytes())),
     RefusalReason.DEPTH_INVALID),
    (dict(stamp=9.0, now=10.0), RefusalReason.STALE),
])
def test_bad_frames_are_refused(kwargs, reason):
    refusal = frame_check(**kwargs)
    assert isinstance(refusal, Refusal) and refusal.reason is reason
    assert str(refusal).startswith(reason.value)


def _old_widths(messages, finger_names):
    """The detector's opening by stamp before it merged topics: each message with every finger
    joint gives (its stamp, the sum of its finger positions); the reference for one topic."""
    widths = []
    for names, positions, _velocities, stamp in messages:
        try:
            width = sum(positions[names.index(name)] for name in finger_names)
        except (ValueError, IndexError):
            continue
        widths.append((stamp, float(width)))
    return widths


def test_finger_widths_from_one_topic_are_as_before():
    """One topic with every joint (the simulator's /joint_states): the same (stamp, opening)
    pairs, bit for bit, as the single-topic detector kept."""
    from fr5_rl.config import load_robot_spec
    from fr5_rl.ros.detector_node import FingerWidths

    spec = load_robot_spec()
    names = list(spec.finger_joint_names) + list(spec.joint_names)  # any order: by name
    rng = np.random.default_rng(3)
    messages = [(names, tuple(float(v) for v in rng.uniform(0.0, 0.04, len(names))),
                 tuple(float(v) for v in rng.normal(size=len(names))), 100.0 + 0.005 * i) for i in range(50)]
    widths = FingerWidths(spec.finger_joint_names, 400)
    for i, message in enumerate(messages):
        widths.add(*message, received=float(i))
    assert list(widths.widths) == _old_widths(messages, spec.finger_joint_names)
    assert widths.at(100.0 + 0.005 * 7 + 0.001) == _old_widths(messages, spec.finger_joint_names)[7][1]
    assert widths.at(200.0) is None


def test_commanded_widths_are_the_newest_arrived_by_a_stamp():
    """A frame's command is the newest that had reached the node by the frame's stamp: a command
    sent after the capture (the camera's 60-150 ms latency) says nothing about that frame; NaN is
    skipped."""
    from fr5_rl.ros.detector_node import CommandedWidths

    commanded = CommandedWidths(3)
    assert commanded.at(5.0) is None
    commanded.add(0.08, 1.0)
    commanded.add(0.0, 2.0)
    commanded.add(float("nan"), 2.5)
    assert commanded.at(0.5) is None and commanded.at(1.5) == 0.08 and commanded.at(2.7) == 0.0
    commanded.add(0.07, 3.0)
    commanded.add(0.06, 4.0)  # keeps 3: the one of 1.0 is gone
    assert commanded.at(1.5) is None and commanded.at(3.5) == 0.07


def test_finger_widths_merge_the_arm_and_gripper_topics_by_name():
    """The vendor chain: j1..j6 on /frrobot/joint_states, the fingers on the gripper bridge's
    topic. The arm's messages add nothing, the gripper's add the opening with their stamp; a
    gripper message with NaN is refused, and the opening is unknown until every finger is heard."""
    from fr5_rl.config import load_robot_spec
    from fr5_rl.ros.detector_node import FingerWidths

    spec = load_robot_spec()
    left, right = spec.finger_joint_names
    widths = FingerWidths(spec.finger_joint_names, 400)
    arm = list(spec.joint_names)
    widths.add(arm, [0.0] * 6, [0.0] * 6, 10.0, 1.0)
    widths.add([left], [0.01], [], 10.01, 1.01)
    assert widths.at(10.0) is None and not widths.heard()  # the other finger not heard of yet
    widths.add([right, left], [0.015, 0.02], [], 10.02, 1.02)
    assert widths.heard() and widths.at(10.5) is None  # a gap in the read-back, not a missing gripper
    widths.add(arm, [0.1] * 6, [0.0] * 6, 10.03, 1.03)
    assert list(widths.widths) == [(10.02, 0.02 + 0.015)]
    widths.add([left], [0.005], [], 10.04, 1.04)  # one finger: merged with the other's last value
    assert list(widths.widths)[-1] == (10.02, 0.005 + 0.015)  # stamped with the older finger's
    widths.add([left, right], [float("nan"), 0.0], [], 10.05, 1.05)
    widths.add([left], [0.001], [], 10.06, 1.06)  # held until a good message brings both fingers
    assert len(widths.widths) == 2
    widths.add([left, right], [0.001, 0.002], [], 10.07, 1.07)
    assert list(widths.widths)[-1] == (10.07, 0.001 + 0.002)
    assert widths.at(10.03) == pytest.approx(0.02)  # of two at 10.02, the newer


def test_detector_takes_a_list_of_joint_state_topics():
    from fr5_rl.config import load_yaml, typed
    from fr5_rl.ros.detector_node import DetectorNodeParams

    values = load_yaml("detector")
    assert typed(DetectorNodeParams, values, "detector.yaml").joint_states_topics == ["/joint_states"]
    vendor = ["/frrobot/joint_states", "/fr5/gripper/joint_states"]
    assert typed(DetectorNodeParams, {**values, "joint_states_topics": vendor}, "x").joint_states_topics == vendor
    for bad in ([], ["/a", "/a"]):
        with pytest.raises(ConfigError, match="joint_states_topics"):
            typed(DetectorNodeParams, {**values, "joint_states_topics": bad}, "x")


def test_near_an_upright_object_is_near_its_axis_from_bottom_to_top():
    from fr5_rl.objects import distance_to_upright_object

    centre = (0.5, -0.2, 0.05)
    assert distance_to_upright_object((0.5, -0.2, 0.095), centre, 0.05) == pytest.approx(0.0)  # at its top
    assert distance_to_upright_object((0.5, -0.2, 0.13), centre, 0.05) == pytest.approx(0.03)
    assert distance_to_upright_object((0.53, -0.16, 0.02), centre, 0.05) == pytest.approx(0.05)  # beside it
    assert distance_to_upright_object((0.53, -0.2, 0.14), centre, 0.05) == pytest.approx(math.hypot(0.03, 0.04))
    assert distance_to_upright_object((0.5, -0.2, 0.095), centre, 0.0) == pytest.approx(0.045)  # to the centre


def test_the_environment_takes_a_tall_object_into_the_hand_as_the_tracker_does():
    """The environment's model of the tracker measures from the object's axis too: a tall object
    lifted with the tcp 4.5 cm above its centre is in the hand."""
    import dataclasses as dc

    from fr5_rl.env_config import load_env_config
    from fr5_rl.tasks import TaskState, held_as_the_camera_sees

    randomisation = load_env_config().randomisation
    rest_z, lifted = 0.05, 0.08
    state = TaskState(joint_positions=(0.0,) * 6, joint_velocities=(0.0,) * 6, tcp_position=(0.5, 0.0, lifted + 0.045),
                      tcp_approach_axis=(0.0, 0.0, -1.0), gripper_width=0.04, tcp_to_object_distance=0.045,
                      object_position=(0.5, 0.0, lifted), object_up_axis=(0.0, 0.0, 1.0),
                      object_start_position=(0.5, 0.0, rest_z), robot_table_contact=False, arm_object_contact=False,
                      fingers_object_contact=2, tcp_in_workspace=True)
    assert held_as_the_camera_sees(state, 0.04, rest_z, randomisation, object_half_height=0.05)
    assert not held_as_the_camera_sees(state, 0.04, rest_z, randomisation, object_half_height=0.0)  # from its centre
    beside = dc.replace(state, tcp_position=(0.545, 0.0, lifted))
    assert not held_as_the_camera_sees(beside, 0.04, rest_z, randomisation, object_half_height=0.05)


def test_the_environments_model_of_in_the_hand_uses_the_trackers_thresholds():
    """One rule, two places: the environment's ``held_as_the_camera_sees`` (what training sees)
    and the detector's tracker (what the node publishes) must agree on when fingers hold it."""
    from fr5_rl.env_config import load_env_config

    randomisation = load_env_config().randomisation
    tracker = TrackerSettings.from_yaml()
    assert randomisation.target_in_hand_radius == tracker.grasp_radius
    assert randomisation.target_in_hand_width_margin == tracker.grasp_width_margin
