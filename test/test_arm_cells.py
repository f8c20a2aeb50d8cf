"""Each arm's shipped cell (config/static_transforms_<arm>.yaml, fr5_rl.transforms.transforms_of_arm):
the simulated camera sees the arm's whole placement region, which the FR5's mount would not, and
every consumer of the shipped file gets the arm's own."""
import numpy as np
import pytest

from fr5_rl.config import DEFAULT_ROBOT, robot_names
from fr5_rl.env_config import load_env_config
from fr5_rl.perception.camera_model import Intrinsics
from fr5_rl.transforms import load_transform_files, transform_in, transforms_of_arm


def _intrinsics() -> Intrinsics:
    from fr5_rl.config import load_yaml

    camera = load_yaml("camera")
    return Intrinsics(camera["width"], camera["height"], camera["fx"], camera["fy"], camera["cx"], camera["cy"])

def _pixels_of_region(robot: str, transforms_robot: str) -> np.ndarray:
    """The placement region's corners, on the table and 12 cm above it (the tallest object), in
    the image of the camera mounted as ``transforms_robot``'s cell says."""
    cfg = load_env_config({"robot": robot})
    (x0, y0), (x1, y1) = cfg.object.region_low, cfg.object.region_high
    corners = np.array([[x, y, z, 1.0] for x in (x0, x1) for y in (y0, y1) for z in (0.0, 0.12)])
    entries = load_transform_files(["static_transforms", "camera_frames"], transforms_robot)
    optical_in_base = transform_in(entries, "base_link", "camera_color_optical_frame")
    in_optical = (np.linalg.inv(optical_in_base) @ corners.T).T[:, :3]
    assert np.all(in_optical[:, 2] > 0.3), "the region is behind or at the camera"
    return _intrinsics().project(in_optical)

def _inside(pixels: np.ndarray, margin: float = 10.0) -> bool:
    intrinsics = _intrinsics()
    return bool(np.all((pixels[:, 0] >= margin) & (pixels[:, 0] <= intrinsics.width - margin)
                       & (pixels[:, 1] >= margin) & (pixels[:, 1] <= intrinsics.height - margin)))

@pytest.mark.parametrize("robot", robot_names())
def test_the_arms_camera_sees_its_whole_placement_region(robot):
    assert _inside(_pixels_of_region(robot, robot))

def test_the_fr5s_mount_would_not_see_a_large_arms_region():
    assert not _inside(_pixels_of_region("fr20", DEFAULT_ROBOT))

@pytest.mark.parametrize("robot", [name for name in robot_names() if name != DEFAULT_ROBOT])
def test_the_shipped_file_stands_for_the_arms_cell_and_a_calibration_is_kept(robot, tmp_path):
    table = transform_in(load_transform_files(["static_transforms"], robot), "base_link", "table")
    assert table[:2, 3] == pytest.approx(load_env_config({"robot": robot}).table.center_xy)
    mine = tmp_path / "my_mount.yaml"
    assert transforms_of_arm(mine, robot) == mine
    assert transforms_of_arm("static_transforms", DEFAULT_ROBOT) == "static_transforms"


def _starts_the_detector_misses(robot: str, placements: int) -> list:
    """Of ``placements`` episode starts of the place task (objects of every kind, the arm at its
    noisy home pose), the object positions (x, y, m) the detector does not report from the arm's
    cell camera."""
    from fr5_rl.config import load_yaml
    from fr5_rl.envs import FR5Env
    from fr5_rl.perception.detector import Detection, DetectorSettings, ObjectDetector, TableRegion
    from fr5_rl.sim.camera import SimulatedCamera

    camera_cfg, intrinsics = load_yaml("camera"), _intrinsics()
    entries = load_transform_files([camera_cfg["mount_config"], camera_cfg["frames_config"]], robot)
    pose = transform_in(entries, camera_cfg["base_frame"], camera_cfg["frame_id"])
    env = FR5Env("place", config={"robot": robot, "object": {"variety": {"enabled": True}},
                                  "observation": {"object_features": True}})
    names = list(env.robot_spec.joint_names) + list(env.robot_spec.finger_joint_names)
    camera = SimulatedCamera(env.cfg, names, pose, intrinsics.opengl_projection(camera_cfg["near"], camera_cfg["far"]),
                             intrinsics.width, intrinsics.height, camera_cfg["near"], camera_cfg["far"], "tiny")
    detector = ObjectDetector(DetectorSettings.from_yaml(), TableRegion.from_env(env.cfg))
    unseen = []
    try:
        for seed in range(8_000_000, 8_000_000 + placements):
            env.reset(seed=seed)
            states, pose_of_object, scene = env.episode.joint_states(), env.episode.object_pose(), env.episode.scene()
            camera.set_joints(dict(zip(states.names, states.positions)))
            camera.set_object(scene.object_shape, scene.object_dims, pose_of_object.position, pose_of_object.quaternion)
            _, depth = camera.render()
            if not isinstance(detector.detect(depth, intrinsics, pose), Detection):
                unseen.append(tuple(round(v, 3) for v in pose_of_object.position[:2]))
    finally:
        camera.close()
        env.close()
    return unseen


@pytest.mark.parametrize("robot", robot_names())
def test_the_arm_at_home_hides_no_object_from_its_cell_camera(robot):
    """The arm starts every episode at home: its gripper must not stand between the camera and any
    object, or the policy node waits for a first target that never comes. The FR3's family home
    (forearm horizontal) hung its gripper 0.18 m over the region: 3 of these 60 starts (22 of 200)
    hidden, two rehearsal episodes of 20 lost (stop 68); raised, none."""
    assert _starts_the_detector_misses(robot, 60) == []
