"""Static transforms node: config/static_transforms.yaml (and more files) on /tf_static, in one call.

``tf2_ros.StaticTransformBroadcaster.sendTransform`` (rospy) replaces what the node published
before, so every transform of every file goes out in a single call. Parameters:

- ``~config`` (str or list of str): a transforms file, or several (paths or names in config/),
  e.g. ``[static_transforms, camera_frames]`` when the camera driver's ``publish_tf`` is false;
  default: the package's config/static_transforms.yaml. A frame given a parent in two files is
  refused. For an arm other than the FR5 (``/robot_description``'s), the shipped file stands for
  that arm's cell, config/static_transforms_<arm>.yaml.
- ``~warn_simulator_mount`` (bool, default false; real_policy.launch: true): while a file still
  carries ``simulator_default: true`` (the shipped camera mount, the simulator's), log a loud
  warning at start and every minute: on a real cell the camera is somewhere else.
"""
from __future__ import annotations

import sys
from typing import Dict, List, Sequence, Union

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped

from ..config import ConfigError, load_typed
from ..transforms import SHIPPED_TRANSFORMS, StaticTransforms, load_transform_files, quaternion_from_matrix, transforms_of_arm
from .params import described_arm, exit_if_help_asked
from .lifetime import init_node


def to_messages(entries: Sequence[Dict], stamp: rospy.Time) -> List[TransformStamped]:
    """TransformStamped messages (parent -> child) for the configured entries.

    :param entries: :func:`fr5_rl.transforms.load_static_transforms` entries (xyz in m, matrix 4x4).
    :param stamp: the header stamp of every message.
    """
    messages = []
    for entry in entries:
        message = TransformStamped()
        message.header.stamp = stamp
        message.header.frame_id = entry["parent"]
        message.child_frame_id = entry["child"]
        x, y, z = entry["xyz"]
        message.transform.translation.x, message.transform.translation.y, message.transform.translation.z = x, y, z
        qx, qy, qz, qw = quaternion_from_matrix(entry["matrix"][:3, :3])
        rotation = message.transform.rotation
        rotation.x, rotation.y, rotation.z, rotation.w = qx, qy, qz, qw
        messages.append(message)
    return messages


def config_files(value: Union[str, Sequence[str]]) -> List[str]:
    """The ``~config`` parameter as a list of files (one file may be given as a plain string).

    :raises ConfigError: not a string or a non-empty list of strings.
    """
    files = [value] if isinstance(value, str) else value
    if not isinstance(files, (list, tuple)) or not files or not all(isinstance(f, str) and f for f in files):
        raise ConfigError(f"~config must be a file or a non-empty list of files, got {value!r}")
    return list(files)


def simulator_mount_files(files: Sequence[str], entries: Sequence[Dict]) -> List[str]:
    """The files among ``files`` marked ``simulator_default`` that set a camera mount (a
    transform to a frame whose name starts with ``camera``)."""
    mounting = {entry["source"] for entry in entries if entry["child"].startswith("camera")}
    return [path for path in files if path in mounting and load_typed(StaticTransforms, path).simulator_default]


def simulator_mount_warning(files: Sequence[str]) -> str:
    """The warning's text (several lines, so it stands out in a launch's output)."""
    bar = "!" * 78
    return (f"\n{bar}\n  CAMERA MOUNT NOT CALIBRATED: {', '.join(files)} is the SIMULATOR's camera pose\n"
            f"  (simulator_default: true). On a real cell every target seen by the camera lands\n"
            f"  where the simulated camera would have seen it, not where the object is.\n"
            f"  Calibrate first: rosrun fr5_rl calibrate_camera.py --out my_mount.yaml, then\n"
            f"  real_policy.launch static_transforms:=$(pwd)/my_mount.yaml (docs/sim_to_real.md).\n{bar}")


def main() -> None:
    exit_if_help_asked("static_transforms_node.py", __doc__.split("\n\n")[0] + "\n\n~config: a path or a name in "
                       "config/, or a list of them (default: static_transforms)")
    init_node("static_transforms")
    try:
        files = config_files(rospy.get_param("~config", SHIPPED_TRANSFORMS))
        # The arm the launch describes: the shipped cell's file stands for that arm's own.
        files = [str(transforms_of_arm(path, described_arm())) for path in files]
        entries = load_transform_files(files)
        uncalibrated = simulator_mount_files(files, entries) if rospy.get_param("~warn_simulator_mount", False) else []
    except ConfigError as error:
        rospy.logfatal(f"static_transforms: {error}")
        sys.exit(1)
    if uncalibrated:
        warning = simulator_mount_warning(uncalibrated)
        rospy.logwarn(warning)
        # Kept on as long as the node runs: a warning at start-up scrolls away.
        rospy.Timer(rospy.Duration(60.0), lambda _event: rospy.logwarn(warning))
    broadcaster = tf2_ros.StaticTransformBroadcaster()
    broadcaster.sendTransform(to_messages(entries, rospy.Time.now()))
    rospy.loginfo("published %d static transforms: %s", len(entries),
                  ", ".join(f"{e['parent']}->{e['child']}" for e in entries))
    rospy.spin()
