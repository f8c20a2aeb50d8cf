"""The simulated camera: the pinhole model, the rendered projection matching it, the depth image,
the frames (the mount in static_transforms.yaml, the camera's own chain in camera_frames.yaml, as
realsense2_camera publishes it), the joint states it poses the robot with, and render + detect
against the simulator's truth."""
import numpy as np
import pybullet as p
import pytest
import yaml

from fr5_rl.config import ConfigError, load_robot_spec, load_yaml, typed
from fr5_rl.env_config import load_env_config
from fr5_rl.perception.camera_model import Intrinsics, IntrinsicsError
from fr5_rl.perception.detector import Detection, DetectorSettings, ObjectDetector, TableRegion
from fr5_rl.ros.camera_node import CameraNodeParams, JointStateHistory
from fr5_rl.ros.static_transforms import config_files
from fr5_rl.sim.camera import SimulatedCamera, depth_to_millimetres
from fr5_rl.transforms import load_static_transforms, load_transform_files, quaternion_from_matrix, transform_in

CAMERA = load_yaml("camera")
K = Intrinsics(CAMERA["width"], CAMERA["height"], CAMERA["fx"], CAMERA["fy"], CAMERA["cx"], CAMERA["cy"])
FRAMES = [CAMERA["mount_config"], CAMERA["frames_config"]]
OPTICAL = CAMERA["frame_id"]


def _pose(frame: str = OPTICAL) -> np.ndarray:
    """``frame`` in base_link through the mount and the camera's chain (4x4, m)."""
    return transform_in(load_transform_files(FRAMES), "base_link", frame)


def test_back_projection_inverts_projection():
    rng = np.random.default_rng(0)
    points = rng.uniform([-0.5, -0.4, 0.3], [0.5, 0.4, 2.0], (100, 3))
    pixels = K.project(points)
    np.testing.assert_allclose(K.back_project(pixels[:, 0], pixels[:, 1], points[:, 2]), points, atol=1e-12)
    assert K.project(np.array([0.0, 0.0, 1.0])) == pytest.approx([K.cx, K.cy])


def _pybullet_pixels(points_base, base_from_optical, width, height, fov_deg, near, far):
    """Pixels (ROS convention) of base_link points through PyBullet's own camera matrices
    (computeViewMatrix / computeProjectionMatrixFOV), a reference independent of the pinhole
    code: clip = P V x, then OpenGL's viewport (pixel i spans [i, i+1), row 0 at the top as
    PyBullet's images are)."""
    eye = base_from_optical[:3, 3]
    view = np.array(p.computeViewMatrix(eye.tolist(), (eye + base_from_optical[:3, 2]).tolist(),
                                        (-base_from_optical[:3, 1]).tolist())).reshape(4, 4).T
    projection = np.array(p.computeProjectionMatrixFOV(fov_deg, width / height, near, far)).reshape(4, 4).T
    clip = projection @ view @ np.c_[points_base, np.ones(len(points_base))].T
    ndc = clip[:3] / clip[3]
    pixels = np.stack([(ndc[0] + 1.0) / 2.0 * width - 0.5, (1.0 - ndc[1]) / 2.0 * height - 0.5], axis=-1)
    return pixels, view, projection


def test_pinhole_matches_pybullets_own_camera_matrices():
    """The detector's pinhole model and the camera the simulator renders with agree with
    PyBullet's view/projection helpers (fx = fy, principal point at the image centre, the case
    those helpers can express) to 1e-3 px (PyBullet's matrices are float32), all over the view."""
    base_from_optical = _pose()
    width, height, f = K.width, K.height, K.fx
    centred = Intrinsics(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)
    rng = np.random.default_rng(4)
    optical = rng.uniform([-0.4, -0.3, 0.4], [0.4, 0.3, 2.0], (200, 3))
    optical = optical[np.all(np.abs(centred.project(optical) - [width / 2, height / 2]) < [width / 2, height / 2],
                             axis=1)]
    points_base = (base_from_optical @ np.c_[optical, np.ones(len(optical))].T).T[:, :3]
    fov = np.degrees(2.0 * np.arctan(height / 2.0 / f))
    near, far = CAMERA["near"], CAMERA["far"]
    reference, view, projection = _pybullet_pixels(points_base, base_from_optical, width, height, fov, near, far)
    assert len(optical) > 50
    np.testing.assert_allclose(centred.project(optical), reference, atol=1e-3)
    # The matrices sim/camera.py hands to getCameraImage are PyBullet's own for this camera.
    np.testing.assert_allclose(centred.opengl_projection(near, far), projection, atol=1e-5)
    spec = load_robot_spec()
    world = SimulatedCamera(load_env_config(), list(spec.joint_names), base_from_optical,
                            centred.opengl_projection(near, far), 64, 48, near, far, "tiny")
    try:
        np.testing.assert_allclose(np.array(world.view).reshape(4, 4).T, view, atol=1e-5)
    finally:
        world.close()


@pytest.mark.parametrize("fx, width", [(0.0, 640), (float("nan"), 640), (615.0, 0)])
def test_unusable_intrinsics_are_refused(fx, width):
    with pytest.raises(IntrinsicsError):
        Intrinsics(width, 480, fx, 615.0, 320.0, 240.0)


def test_optical_frame_follows_rep_103():
    """z forward = camera_color_frame x, x right = its -y, y down = its -z, at its origin: the
    wrapper's quaternion_optical, rpy (-90 deg, 0, -90 deg); camera_color_frame is turned like
    camera_link (a body frame, x forward)."""
    link, color, optical = _pose("camera_link"), _pose("camera_color_frame"), _pose()
    np.testing.assert_allclose(color[:3, :3], link[:3, :3], atol=1e-12)
    np.testing.assert_allclose(optical[:3, 3], color[:3, 3], atol=1e-12)
    np.testing.assert_allclose(optical[:3, 2], color[:3, 0], atol=1e-6)
    np.testing.assert_allclose(optical[:3, 0], -color[:3, 1], atol=1e-6)
    np.testing.assert_allclose(optical[:3, 1], -color[:3, 2], atol=1e-6)
    in_color = np.linalg.inv(color) @ optical
    assert quaternion_from_matrix(in_color[:3, :3]) == pytest.approx((-0.5, 0.5, -0.5, 0.5), abs=1e-6)


def test_colour_sensor_sits_off_camera_link_and_aligned_depth_with_it():
    """The configured colour-sensor offset is where the optical frame is (not camera_link), and
    the aligned depth's body frame is the colour sensor's pose, as the wrapper publishes them."""
    chain = {e["child"]: e for e in load_static_transforms(CAMERA["frames_config"])}
    offset = np.array(chain["camera_color_frame"]["xyz"])
    assert 0.0 < np.linalg.norm(offset) < 0.05  # a D435's colour sensor: ~15 mm off the depth origin
    in_link = np.linalg.inv(_pose("camera_link")) @ _pose()
    np.testing.assert_allclose(in_link[:3, 3], offset, atol=1e-12)
    np.testing.assert_array_equal(chain["camera_aligned_depth_to_color_frame"]["matrix"],
                                  chain["camera_color_frame"]["matrix"])
    assert chain["camera_aligned_depth_to_color_frame"]["parent"] == "camera_link"


def test_project_publishes_only_the_mount_and_every_frame_has_one_parent(tmp_path):
    """static_transforms.yaml: base_link -> camera_link and the table only; the camera's chain is
    camera_frames.yaml's, and a mount file that still holds a camera frame is refused together
    with it (the optical frame would have two parents)."""
    mount = load_static_transforms(CAMERA["mount_config"])
    assert {(e["parent"], e["child"]) for e in mount} == {("base_link", "camera_link"), ("base_link", "table")}
    chain = load_static_transforms(CAMERA["frames_config"])
    assert {(e["parent"], e["child"]) for e in chain} == {
        ("camera_link", "camera_color_frame"), ("camera_color_frame", OPTICAL),
        ("camera_link", "camera_aligned_depth_to_color_frame")}
    both = load_transform_files(FRAMES)
    assert len({e["child"] for e in both}) == len(both) == len(mount) + len(chain)
    old = tmp_path / "old_static_transforms.yaml"
    old.write_text("transforms:\n"
                   "  - {parent: base_link, child: camera_link, xyz: [0, 0, 1], rpy: [0, 0, 0]}\n"
                   f"  - {{parent: camera_link, child: {OPTICAL}, xyz: [0, 0, 0], rpy: [-1.570796, 0, -1.570796]}}\n")
    with pytest.raises(ConfigError, match=f"{OPTICAL} has a parent in both"):
        load_transform_files([old, CAMERA["frames_config"]])
    assert config_files("static_transforms") == ["static_transforms"]
    assert config_files(FRAMES) == FRAMES
    for bad in ([], [""], 3, ["a", 3]):
        with pytest.raises(ConfigError, match="~config"):
            config_files(bad)


def _params(**changes) -> CameraNodeParams:
    return typed(CameraNodeParams, {**CAMERA, **changes}, "camera.yaml")


def test_camera_renders_from_the_chain_it_publishes(tmp_path):
    """One source: the pose the node renders from is the mount times exactly the entries it
    publishes on /tf_static; with a zero colour-sensor offset it is, bit for bit, the pose of the
    former single entry camera_link -> optical frame, so the images are today's."""
    pose, frames = _params().transforms()
    np.testing.assert_array_equal(pose, _pose())
    assert [e["child"] for e in frames] == [e["child"] for e in load_static_transforms(CAMERA["frames_config"])]
    mount_only = [e for e in load_static_transforms(CAMERA["mount_config"]) if e["child"] == "camera_link"]
    chain = load_yaml(CAMERA["frames_config"])
    for entry in chain["transforms"]:
        if entry["parent"] == "camera_link":
            entry["xyz"] = [0.0, 0.0, 0.0]
    zero = tmp_path / "camera_frames_zero.yaml"
    zero.write_text(yaml.safe_dump(chain))
    optical_entry = next(e for e in load_static_transforms(zero) if e["child"] == OPTICAL)
    former = transform_in(mount_only + [{**optical_entry, "parent": "camera_link"}], "base_link", OPTICAL)
    np.testing.assert_array_equal(_params(frames_config=str(zero)).transforms()[0], former)
    assert np.linalg.norm(pose[:3, 3] - former[:3, 3]) > 0.01  # the default offset does move the camera
    with pytest.raises(ConfigError, match="no transform to the camera's frame_id"):
        _params(frame_id="camera_depth_optical_frame").transforms()


def test_joint_states_with_some_joints_keep_the_others():
    """The camera poses every joint it has heard of: a message with only some (by name) keeps the
    rest; the state of the object's stamp is used when held, else the newest."""
    history = JointStateHistory(3)
    assert history.at(5) is None
    history.add(10, ["j1", "j2", "finger_left"], [0.1, 0.2, 0.03])
    history.add(20, ["j2"], [0.5])
    history.add(30, ["finger_left", "j1"], [0.01, -0.1])
    assert history.at(20) == (20, {"j1": 0.1, "j2": 0.5, "finger_left": 0.03})
    assert history.at(30) == (30, {"j1": -0.1, "j2": 0.5, "finger_left": 0.01})
    assert history.at(25) == history.at(30)
    history.add(40, ["j3"], [1.0])
    assert history.at(10) == (40, {"j1": -0.1, "j2": 0.5, "finger_left": 0.01, "j3": 1.0})  # 10 dropped


def test_depth_in_millimetres_with_zero_for_no_data():
    depth = np.array([[0.0, 0.9424], [1.0, 70.0]])
    np.testing.assert_array_equal(depth_to_millimetres(depth), [[0, 942], [1000, 65535]])
    rng = np.random.default_rng(0)
    noisy = depth_to_millimetres(np.full((100, 100), 1.0), noise_per_m2=0.002, rng=rng).astype(float)
    assert noisy.std() == pytest.approx(2.0, rel=0.15) and noisy.mean() == pytest.approx(1000.0, abs=0.5)
    with pytest.raises(ValueError):
        depth_to_millimetres(depth, noise_per_m2=0.001)


@pytest.fixture(scope="module")
def camera():
    spec = load_robot_spec()
    names = list(spec.joint_names) + list(spec.finger_joint_names)
    pose = _pose()
    cam = SimulatedCamera(load_env_config(), names, pose, K.opengl_projection(CAMERA["near"], CAMERA["far"]),
                          K.width, K.height, CAMERA["near"], CAMERA["far"], "tiny")
    cam.set_joints(dict(zip(spec.joint_names, spec.home_joint_positions)))
    yield cam, pose
    cam.close()


def test_rendered_depth_obeys_the_camera_model(camera):
    """A pixel's depth, back-projected through the CameraInfo model, lies on the table plane."""
    cam, pose = camera
    cam.set_object("cylinder", (0.025, 0.06), (-0.6, 0.2, 0.03), (0, 0, 0, 1))
    rgb, depth = cam.render()
    assert rgb.shape == (K.height, K.width, 3) and rgb.dtype == np.uint8 and depth.dtype == np.float32
    for u, v in ((40, 460), (600, 450), (322, 300)):
        point = pose @ np.array([*K.back_project(u, v, depth[v, u]), 1.0])
        assert point[2] == pytest.approx(0.0, abs=1e-3), (u, v, point)


def test_render_then_detect_finds_the_true_centre(camera):
    cam, pose = camera
    env = load_env_config()
    detector = ObjectDetector(DetectorSettings.from_yaml(), TableRegion.from_env(env))
    for position in ((-0.40, -0.25, 0.03), (-0.65, 0.1, 0.03), (-0.5, 0.28, 0.03)):
        cam.set_object("cylinder", (0.025, 0.06), position, (0, 0, 0.3826834, 0.9238795))
        rgb, depth = cam.render()
        found = detector.detect(depth_to_millimetres(depth).astype(np.float32) * 0.001, K, pose, rgb)
        assert isinstance(found, Detection), found
        assert np.linalg.norm(np.subtract(found.position_table, position)) < 0.003, (found, position)
        # The colour sensor's offset matters: placed at camera_link instead, the object is off by it.
        link_pose = pose.copy()
        link_pose[:3, 3] = _pose("camera_link")[:3, 3]
        off = detector.detect(depth_to_millimetres(depth).astype(np.float32) * 0.001, K, link_pose, rgb)
        if isinstance(off, Detection):
            assert np.linalg.norm(np.subtract(off.position_table, position)) > 0.01


def test_transform_in_chains_configured_entries_and_refuses_unconnected_frames():
    from fr5_rl.config import ConfigError
    from fr5_rl.transforms import matrix_from_xyz_rpy

    first = matrix_from_xyz_rpy([1.0, 0.0, 0.0], [0.0, 0.0, 1.5707963])
    second = matrix_from_xyz_rpy([0.0, 2.0, 0.0], [0.0, 0.0, 0.0])
    entries = [{"parent": "a", "child": "b", "matrix": first}, {"parent": "b", "child": "c", "matrix": second}]
    assert np.allclose(transform_in(entries, "a", "b"), first)
    chained = transform_in(entries, "a", "c")
    assert np.allclose(chained, first @ second)
    assert np.allclose(chained[:3, 3], [-1.0, 0.0, 0.0], atol=1e-6)  # (0, 2) turned by 90 deg, then +x 1
    assert np.allclose(transform_in(entries, "c", "c"), np.eye(4))
    with pytest.raises(ConfigError, match="do not connect"):
        transform_in(entries, "c", "a")
    looped = entries + [{"parent": "c", "child": "a", "matrix": second}]
    with pytest.raises(ConfigError, match="do not connect"):
        transform_in(looped, "x", "c")
