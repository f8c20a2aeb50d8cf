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
