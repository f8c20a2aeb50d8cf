"""The loud warning of real_policy.launch while the camera mount is still the simulator's."""
from __future__ import annotations

from fr5_rl.ros.static_transforms import simulator_mount_files, simulator_mount_warning
from fr5_rl.transforms import load_transform_files

MOUNT = """transforms:
  - parent: base_link
    child: camera_link
    xyz: [-1.2, 0.01, 0.74]
    rpy: [0.0, 0.78, 0.01]
"""


def test_the_shipped_mount_is_marked_as_the_simulators():
    files = ["static_transforms", "camera_frames"]
    assert simulator_mount_files(files, load_transform_files(files)) == ["static_transforms"]
    assert "CAMERA MOUNT NOT CALIBRATED" in simulator_mount_warning(["static_transforms"])


def test_a_measured_mount_without_the_mark_is_not_warned_about(tmp_path):
    measured = tmp_path / "my_mount.yaml"
    measured.write_text(MOUNT)
    files = [str(measured), "camera_frames"]
    assert simulator_mount_files(files, load_transform_files(files)) == []


def test_a_marked_file_without_a_camera_is_not_warned_about(tmp_path):
    table_only = tmp_path / "table.yaml"
    table_only.write_text("simulator_default: true\ntransforms:\n  - {parent: base_link, child: table, "
                          "xyz: [0, 0, 0], rpy: [0, 0, 0]}\n")
    assert simulator_mount_files([str(table_only)], load_transform_files([str(table_only)])) == []
