"""The simulated camera: the pinhole model, the rendered projection matching it, the depth image,
the optical frame, and render + detect against the simulator's truth."""
import numpy as np
import pybullet as p
import pytest

from fr5_rl.config import load_env_config, load_robot_spec, load_yaml
from fr5_rl.runtime.detection import Detection, DetectorSettings, ObjectDetector
from fr5_rl.runtime.pinhole import Intrinsics, IntrinsicsError
from fr5_rl.sim.camera import SimulatedCamera, depth_to_millimetres
from fr5_rl.transforms import load_static_transforms, transform_in

CAMERA = load_yaml("camera")
K = Intrinsics(CAMERA["width"], CAMERA["height"], CAMERA["fx"], CAMERA["fy"], CAMERA["cx"], CAMERA["cy"])


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
    base_from_optical = transform_in(load_static_transforms(), "base_link", CAMERA["frame_id"])
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
    """z forward = camera_link x, x right = camera_link -y, y down = camera_link -z."""
    link = transform_in(load_static_transforms(), "base_link", "camera_link")
    optical = transform_in(load_static_transforms(), "base_link", CAMERA["frame_id"])
    np.testing.assert_allclose(optical[:3, 3], link[:3, 3], atol=1e-9)
    np.testing.assert_allclose(optical[:3, 2], link[:3, 0], atol=1e-6)
    np.testing.assert_allclose(optical[:3, 0], -link[:3, 1], atol=1e-6)
    np.testing.assert_allclose(optical[:3, 1], -link[:3, 2], atol=1e-6)


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
    pose = transform_in(load_static_transforms(), "base_link", CAMERA["frame_id"])
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
    detector = ObjectDetector(DetectorSettings(tuple(env["object"]["region_low"]), tuple(env["object"]["region_high"])))
    for position in ((-0.40, -0.25, 0.03), (-0.65, 0.1, 0.03), (-0.5, 0.28, 0.03)):
        cam.set_object("cylinder", (0.025, 0.06), position, (0, 0, 0.3826834, 0.9238795))
        rgb, depth = cam.render()
        found = detector.detect(depth_to_millimetres(depth).astype(np.float32) * 0.001, K, pose, rgb)
        assert isinstance(found, Detection), found
        assert np.linalg.norm(np.subtract(found.position_table, position)) < 0.003, (found, position)


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
    with pytest.raises(ConfigError, match="does not connect"):
        transform_in(entries, "c", "a")
    looped = entries + [{"parent": "c", "child": "a", "matrix": second}]
    with pytest.raises(ConfigError, match="does not connect"):
        transform_in(looped, "x", "c")
