"""Scenes of several objects (fr5_rl.scenes) and the detector that reports each one
(fr5_rl.perception.scene_detector), through the simulated RealSense of the shipped mount (issue #54)."""
import dataclasses
import math

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec, load_yaml
from fr5_rl.env_config import load_env_config
from fr5_rl.objects import ObjectShape
from fr5_rl.perception.detector import DetectorSettings, ObjectDetector, RefusalReason, TableRegion
from fr5_rl.perception.scene_detector import SceneLimits, _convexity, detect_scene
from fr5_rl.scenes import SceneObject, SceneSettings, draw_scene

ENV = load_env_config()
SETTINGS = SceneSettings.from_yaml()


def footprint_gap(a: SceneObject, b: SceneObject) -> float:
    return math.hypot(a.position[0] - b.position[0], a.position[1] - b.position[1]) \
        - a.footprint_radius - b.footprint_radius


def test_a_scene_is_drawn_from_its_seed_inside_the_region_with_its_gaps():
    low, high = np.asarray(ENV.object.region_low), np.asarray(ENV.object.region_high)
    sizes = []
    for seed in range(40):
        scene = draw_scene(np.random.default_rng(seed), ENV, SETTINGS)
        again = draw_scene(np.random.default_rng(seed), ENV, SETTINGS)
        assert scene == again
        assert SETTINGS.count[0] <= len(scene) <= SETTINGS.count[1]
        sizes.append(len(scene))
        for k, obj in enumerate(scene):
            assert np.all(low <= obj.position[:2]) and np.all(np.asarray(obj.position[:2]) <= high)
            assert obj.position[2] == pytest.approx(ENV.table.top_height + 0.5 * obj.shape.size[2])
            if obj.shape.label == "rectangular box":
                assert obj.shape.size[0] - obj.shape.size[1] >= SETTINGS.rectangular_min_difference - 1e-9
            for other in scene[:k]:
                assert footprint_gap(obj, other) >= SETTINGS.min_gap - 1e-9
    assert len(set(sizes)) > 2  # the count is drawn


def test_touching_objects_stand_face_to_face():
    settings = dataclasses.replace(SETTINGS, touching_share=1.0)
    touching = 0
    for seed in range(20):
        scene = draw_scene(np.random.default_rng(seed), ENV, settings)
        for before, obj in zip(scene, scene[1:]):
            if obj.touching:
                touching += 1
                distance = math.hypot(obj.position[0] - before.position[0], obj.position[1] - before.position[1])
                assert distance == pytest.approx(0.5 * before.shape.size[0] + 0.5 * obj.shape.size[0])
                assert obj.yaw == before.yaw
    assert touching > 10


def test_scene_settings_are_checked():
    with pytest.raises(ConfigError, match="count"):
        dataclasses.replace(SETTINGS, count=[3, 2]).check("test")
    with pytest.raises(ConfigError, match="touching_share"):
        dataclasses.replace(SETTINGS, touching_share=1.5).check("test")


def test_a_face_of_two_footprints_joined_is_not_convex():
    step = 0.0015  # m between the points, each covering step^2
    grid = np.arange(0.0, 0.05, step)
    x, y = [a.ravel() for a in np.meshgrid(grid, grid)]
    limit = SceneLimits.from_objects(ENV.object.variety, 0.015).settings.min_convexity
    assert _convexity(x, y, np.full(x.size, step ** 2)) > 0.97  # a square
    disc = np.hypot(x - 0.025, y - 0.025) <= 0.025
    assert _convexity(x[disc], y[disc], np.full(disc.sum(), step ** 2)) > 0.95
    ell = (x < 0.02) | (y < 0.02)
    assert _convexity(x[ell], y[ell], np.full(ell.sum(), step ** 2)) < limit
    # Two discs side by side: 0.88 of their hull.
    two = np.concatenate([np.stack([x[disc], y[disc]]), np.stack([x[disc] + 0.05, y[disc]])], axis=1)
    assert _convexity(two[0], two[1], np.full(two.shape[1], step ** 2)) < limit


# ----------------------------------------------------------------------------- through the camera
@pytest.fixture(scope="module")
def camera_view():
    """The shipped camera model and mount, a render-only world with the arm at home, and the detector."""
    from fr5_rl.perception.camera_model import Intrinsics
    from fr5_rl.sim.camera import SimulatedCamera
    from fr5_rl.transforms import load_transform_files, transform_in

    cfg, robot = load_yaml("camera"), load_robot_spec()
    intrinsics = Intrinsics(cfg["width"], cfg["height"], cfg["fx"], cfg["fy"], cfg["cx"], cfg["cy"])
    pose = transform_in(load_transform_files([cfg["mount_config"], cfg["frames_config"]]), cfg["base_frame"],
                        cfg["frame_id"])
    camera = SimulatedCamera(ENV, list(robot.joint_names) + list(robot.finger_joint_names), pose,
                             intrinsics.opengl_projection(cfg["near"], cfg["far"]), intrinsics.width,
                             intrinsics.height, cfg["near"], cfg["far"])
    camera.set_joints(dict(zip(robot.joint_names, robot.home_joint_positions.tolist())))
    detector = ObjectDetector(DetectorSettings.from_yaml(), TableRegion.from_env(ENV))
    limits = SceneLimits.from_objects(ENV.object.variety, SETTINGS.rectangular_min_difference)

    def look(scene):
        camera.set_objects([(obj.shape.kind, obj.dims, obj.position, obj.quaternion) for obj in scene])
        _, depth = camera.render()
        return detect_scene(detector, limits, depth, intrinsics, pose)

    yield look
    camera.close()


def standing(kind: str, size, x: float, y: float, yaw: float = 0.0) -> SceneObject:
    shape = ObjectShape(kind, tuple(size))
    return SceneObject(shape, (x, y, ENV.table.top_height + 0.5 * shape.size[2]), yaw, 0.1)


def test_each_object_of_a_scene_is_found_with_its_kind_yaw_and_size(camera_view):
    scene = [standing("cylinder", (0.05, 0.05, 0.08), -0.62, -0.2),
             standing("box", (0.05, 0.05, 0.06), -0.45, -0.15, 0.4),
             standing("box", (0.07, 0.04, 0.05), -0.6, 0.15, -0.9),
             standing("box", (0.06, 0.035, 0.09), -0.42, 0.2, 1.2)]
    result = camera_view(scene)
    assert not result.refused
    assert len(result.objects) == len(scene)
    for truth in scene:
        found = min(result.objects, key=lambda f: math.dist(f.detection.position_table[:2], truth.position[:2]))
        assert math.dist(found.detection.position_table[:2], truth.position[:2]) < 0.005
        assert found.label == truth.shape.label
        if truth.shape.kind == "box":
            assert math.degrees(truth.shape.yaw_error(found.detection.yaw, truth.yaw)) < 5.0
        assert max(abs(a - b) for a, b in zip(found.detection.extents, truth.shape.size[:2])) < 0.005


def test_objects_touching_are_refused_never_merged(camera_view):
    # Each pair stays narrower than the widest object (7 cm), so that its own rule refuses it.
    cases = {"outline": [standing("cylinder", (0.035, 0.035, 0.08), -0.55, -0.1),
                         standing("cylinder", (0.035, 0.035, 0.08), -0.55, -0.065)],  # two discs joined
             "second top": [standing("box", (0.035, 0.035, 0.10), -0.55, 0.1),
                            standing("box", (0.035, 0.035, 0.04), -0.55, 0.135)],  # a short box against a tall one
             "wider than any object": [standing("box", (0.05, 0.05, 0.06), -0.6, 0.0),
                                       standing("box", (0.05, 0.05, 0.06), -0.55, 0.0)]}
    for rule, pair in cases.items():
        result = camera_view(pair)
        assert not result.objects, rule
        assert [piece.reason for piece in result.refused] == [RefusalReason.TOUCHING], rule
        assert rule in result.refused[0].detail


def test_an_object_behind_another_in_the_cameras_view_is_refused(camera_view):
    # Where the camera looks from, a tall cylinder in front hides part of the one behind it; the one
    # in front is found whole.
    from fr5_rl.transforms import load_transform_files, transform_in

    cfg = load_yaml("camera")
    camera_xy = transform_in(load_transform_files([cfg["mount_config"], cfg["frames_config"]]), cfg["base_frame"],
                             cfg["frame_id"])[:2, 3]
    back_xy = np.array([-0.55, 0.0])
    towards_camera = (camera_xy - back_xy) / np.linalg.norm(camera_xy - back_xy)
    front_xy = back_xy + 0.09 * towards_camera
    scene = [standing("cylinder", (0.05, 0.05, 0.06), *back_xy), standing("cylinder", (0.05, 0.05, 0.12), *front_xy)]
    result = camera_view(scene)
    assert len(result.objects) == 1
    assert math.dist(result.objects[0].detection.position_table[:2], front_xy) < 0.005
    assert [piece.reason for piece in result.refused] == [RefusalReason.OCCLUDED]
    assert "behind another object" in result.refused[0].detail


# ----------------------------------------------------------------------------- ids across frames
def found_at(x: float, y: float, label: str = "cylinder"):
    from fr5_rl.perception.detector import Detection
    from fr5_rl.perception.scene_detector import SceneObjectFound

    return SceneObjectFound(Detection((0.0, 0.0, 1.0), (x, y, 0.04), 0.08, (0.0, 0.0), 10.0, 100), label)


def frame(*objects):
    from fr5_rl.perception.scene_detector import SceneDetection

    return SceneDetection(tuple(objects), ())


def test_ids_follow_each_object_and_survive_a_hidden_moment():
    from fr5_rl.perception.scene_tracker import SceneTracker

    tracker = SceneTracker(gate=0.02, hidden_timeout=2.0)
    first = tracker.update(frame(found_at(-0.5, 0.1), found_at(-0.6, -0.1, "square box")), 0.0)
    a, b = [track_id for track_id, _ in first]
    assert a != b
    # Listed the other way round, each a few millimetres off: the same ids.
    again = tracker.update(frame(found_at(-0.602, -0.099, "square box"), found_at(-0.503, 0.101)), 0.1)
    assert [track_id for track_id, _ in again] == [b, a]
    # The arm hides the cylinder for 1.5 s: it comes back with its id.
    tracker.update(frame(found_at(-0.6, -0.1, "square box")), 0.5)
    assert [track_id for track_id, _ in tracker.update(frame(found_at(-0.5, 0.1)), 1.6)] == [a]
    # Hidden longer than hidden_timeout, or of another kind there, or far from any track: a new id.
    assert tracker.update(frame(found_at(-0.6, -0.1, "square box")), 5.0)[0][0] not in (a, b)
    assert tracker.update(frame(found_at(-0.5, 0.1, "square box")), 5.1)[0][0] not in (a, b)
    assert tracker.update(frame(found_at(-0.4, 0.25)), 5.2)[0][0] not in (a, b)


def test_two_objects_near_one_track_take_one_id_between_them():
    from fr5_rl.perception.scene_tracker import SceneTracker

    tracker = SceneTracker(gate=0.03, hidden_timeout=2.0)
    (a, _), = tracker.update(frame(found_at(-0.5, 0.1)), 0.0)
    ids = [track_id for track_id, _ in tracker.update(frame(found_at(-0.51, 0.1), found_at(-0.495, 0.1)), 0.1)]
    assert ids[1] == a and ids[0] != a  # the nearer keeps it
