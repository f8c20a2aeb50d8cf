"""The tracker carries the object's yaw and shape: seen from the frame, hidden the last seen ones,
in the hand an orientation fixed in the tcp frame that turns with the tcp; and the detector node
publishes that orientation in the frame it publishes the position in. Synthetic depth from
straight above (test_detection's camera and table), boxes drawn by test_detection_shapes."""
import math

import numpy as np
import pytest

from fr5_rl.objects import ObjectShape, yaw_of
from fr5_rl.perception.tracker import TrackedObject, TrackState, rotation_z
from fr5_rl.ros.detector_node import target_pose
from fr5_rl.transforms import matrix_from_quaternion, matrix_from_xyz_rpy, quaternion_from_matrix
from test_detection import TABLE_FROM_OPTICAL, Frames, scene
from test_detection_shapes import shapes_scene

CENTRE = (0.1, -0.05)
LENGTH, WIDTH, HEIGHT, YAW = 0.06, 0.03, 0.05, 0.7  # an oblong box: its longer side at 0.7 rad
GRIPPER_OVER_IT = (0.1, -0.05, 0.045, 0.045, 0.2)   # the gripper above it hides it whole
BOX = ObjectShape("box", (LENGTH, WIDTH, HEIGHT))


def box_view(*robot):
    """Depth (m) of the box, with robot parts (test_detection.scene's boxes) in front of it."""
    return np.minimum(shapes_scene("box", *CENTRE, LENGTH, WIDTH, HEIGHT, YAW), scene(*robot))


def tcp_pose(xyz, yaw):
    """The tcp pointing down (z towards the table) with its x axis at ``yaw`` (rad), at ``xyz``."""
    pose = matrix_from_xyz_rpy(xyz, [math.pi, 0.0, 0.0])
    pose[:3, :3] = rotation_z(yaw) @ pose[:3, :3]
    return pose


def test_seen_then_hidden_keeps_the_yaw_and_shape():
    frames = Frames(hidden_timeout=1.0)
    seen = frames(box_view())
    assert isinstance(seen, TrackedObject) and seen.state is TrackState.SEEN
    assert BOX.yaw_error(seen.yaw, YAW) < math.radians(1.0)
    assert seen.shape.kind == "box"
    assert seen.shape.size == pytest.approx(BOX.size, abs=0.003)
    hidden = frames(box_view(GRIPPER_OVER_IT))
    assert isinstance(hidden, TrackedObject) and hidden.state is TrackState.HIDDEN, hidden
    assert hidden.yaw == seen.yaw and hidden.shape == seen.shape and hidden.orientation_tcp is None


@pytest.mark.parametrize("turn", [0.0, 0.5, -1.2, 2.8])
def test_in_the_hand_the_object_turns_with_the_tcp(turn):
    """Taken with the tcp at some yaw, the orientation published in the tcp frame composed with
    the tcp turned by ``turn`` about the table's z gives the object's yaw turned as much (the
    yaw last seen kept: not squared between the pads, square_width_tolerance 0)."""
    frames = Frames(square_width_tolerance=0.0)
    seen = frames(box_view(), tcp=tcp_pose((0.1, -0.05, 0.3), 0.0), width=0.08)
    centre, yaw = np.array(seen.position_table), seen.yaw
    grasp_yaw = yaw + math.pi / 2.0 + 0.1  # across the box (a bit off: the offset is the object's, kept)
    grasp = tcp_pose(centre + [0.0, 0.0, 0.01], grasp_yaw)
    assert frames(box_view(GRIPPER_OVER_IT), tcp=grasp, width=WIDTH).state is TrackState.HIDDEN  # closing
    held = frames(box_view(GRIPPER_OVER_IT), tcp=grasp, width=WIDTH)
    assert held.state is TrackState.IN_HAND and held.shape == seen.shape
    # As it was taken: the tcp's pose times the orientation in it is the object's, upright at its yaw.
    taken = grasp[:3, :3] @ matrix_from_quaternion((0, 0, 0), held.orientation_tcp)[:3, :3]
    np.testing.assert_allclose(taken, rotation_z(yaw), atol=1e-9)
    # The tcp lifts and turns about the table's z: what tf makes of the published pose turns with it.
    turned = matrix_from_xyz_rpy(centre + [0.0, 0.0, 0.08], [0.0, 0.0, 0.0])
    turned[:3, :3] = rotation_z(turn) @ grasp[:3, :3]
    lifted = frames(scene(GRIPPER_OVER_IT), tcp=turned, width=WIDTH)
    assert lifted.state is TrackState.IN_HAND
    held_tcp, position, quaternion = target_pose(lifted, TABLE_FROM_OPTICAL)
    assert held_tcp and quaternion == lifted.orientation_tcp == held.orientation_tcp  # fixed in the tcp frame
    in_table = turned @ matrix_from_quaternion(position, quaternion)
    expected = yaw + turn
    assert BOX.yaw_error(yaw_of(quaternion_from_matrix(in_table[:3, :3])), expected) < 1e-9
    assert in_table[2, 2] == pytest.approx(1.0)  # still upright
    assert BOX.yaw_error(lifted.yaw, expected) < 1e-9  # the table-frame yaw the tracker keeps, too
    # Let go: it stands where the hand left it, at the yaw the hand turned it to.
    released = frames(scene(GRIPPER_OVER_IT), tcp=turned, width=0.08)
    assert released.state is TrackState.HIDDEN and released.orientation_tcp is None
    assert BOX.yaw_error(released.yaw, expected) < 1e-9 and released.shape == seen.shape


def take_at(frames, offset, width):
    """See the box, then close fingers ``width`` (m) open on it with the tcp's x axis ``offset``
    (rad) from the box's seen yaw; the tracker's object once in the hand, and the seen yaw."""
    seen = frames(box_view(), tcp=tcp_pose((0.1, -0.05, 0.3), 0.0), width=0.08)
    grasp = tcp_pose(np.array(seen.position_table) + [0.0, 0.0, 0.01], seen.yaw + offset)
    frames(box_view(GRIPPER_OVER_IT), tcp=grasp, width=width)  # closing
    held = frames(box_view(GRIPPER_OVER_IT), tcp=grasp, width=width)
    assert held.state is TrackState.IN_HAND
    # The orientation published in the tcp frame says the same yaw as the table-frame one.
    taken = grasp[:3, :3] @ matrix_from_quaternion((0, 0, 0), held.orientation_tcp)[:3, :3]
    np.testing.assert_allclose(taken, rotation_z(held.yaw), atol=1e-9)
    return held, seen


@pytest.mark.parametrize("offset", [0.1, -0.3, 0.6, math.pi / 2.0 + 0.2])
def test_a_box_squared_between_the_pads_takes_their_yaw(offset):
    """Fingers stopped at one of the box's sides have squared it between their pads: nudged while
    hidden, it was carried at the yaw last seen, 17 degrees off (the rehearsal). In the hand its
    yaw is the pads', of the four the nearest to the one last seen."""
    frames = Frames(square_width_tolerance=0.008)
    held, seen = take_at(frames, offset, seen_width(frames))
    pads = seen.yaw + offset  # the tcp's x; a face on each pad: the box's axes along the tcp's
    assert ObjectShape("box", (0.04, 0.04, 0.04)).yaw_error(held.yaw, pads) < 1e-9  # modulo a quarter
    assert abs(math.remainder(held.yaw - seen.yaw, 2.0 * math.pi)) <= math.pi / 4.0 + 1e-9


def seen_width(frames):
    """The box's shorter side as the tracker will have seen it (m)."""
    return Frames(square_width_tolerance=0.0)(box_view()).shape.size[1]


@pytest.mark.parametrize("width_off_its_side", [0.005, 0.009])
def test_fingers_at_none_of_its_sides_keep_the_yaw_last_seen(width_off_its_side):
    """Wider than its sides by more than square_width_tolerance (across its corners): nothing
    says the pads squared it."""
    frames = Frames(square_width_tolerance=0.004)
    held, seen = take_at(frames, 0.3, seen_width(frames) + width_off_its_side)
    assert held.yaw == pytest.approx(seen.yaw, abs=1e-9)


def test_seen_and_hidden_poses_carry_the_yaw_in_the_optical_frame():
    """Published in the image's optical frame, the pose brought back into the table frame is
    upright at the object's yaw (an oblique camera: not the table's axes)."""
    table_from_optical = matrix_from_xyz_rpy([-1.2, 0.0, 0.75], [-2.3, 0.05, -1.5])
    tracked = TrackedObject((-0.5, 0.1, 0.03), TrackState.HIDDEN, 0.0, yaw=-2.0, shape=BOX)
    held, position, quaternion = target_pose(tracked, table_from_optical)
    assert not held
    in_table = table_from_optical @ matrix_from_quaternion(position, quaternion)
    np.testing.assert_allclose(in_table[:3, 3], tracked.position_table, atol=1e-9)
    np.testing.assert_allclose(in_table[:3, :3], rotation_z(-2.0), atol=1e-9)

