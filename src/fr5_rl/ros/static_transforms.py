"""Static transforms node: config/static_transforms.yaml (and more files) on /tf_static, in one call.

``tf2_ros.StaticTransformBroadcaster.sendTransform`` (rospy) replaces what the node published
before, so every transform of every file goes out in a single call. Parameters:

- ``~config`` (str or list of str): a transforms file, or several (paths or names in config/),
  e.g. ``[static_transforms, camera_frames]`` when the camera driver's ``publish_tf`` is false;
  default: the package's config/static_transforms.yaml. A frame given a parent in two files is
  refused.
"""
from __future__ import annotations

import sys
from typing import Dict, List, Sequence, Union

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped

from ..config import ConfigError
from ..transforms import load_transform_files, quaternion_from_matrix
from .params import exit_if_help_asked


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


def main() -> None:
    exit_if_help_asked("static_transforms_node.py", __doc__.split("\n\n")[0] + "\n\n~config: a path or a name in "
                       "config/, or a list of them (default: static_transforms)")
    rospy.init_node("static_transforms")
    try:
        entries = load_transform_files(config_files(rospy.get_param("~config", "static_transforms")))
    except ConfigError as error:
        rospy.logfatal(f"static_transforms: {error}")
        sys.exit(1)
    broadcaster = tf2_ros.StaticTransformBroadcaster()
    broadcaster.sendTransform(to_messages(entries, rospy.Time.now()))
    rospy.loginfo("published %d static transforms: %s", len(entries),
                  ", ".join(f"{e['parent']}->{e['child']}" for e in entries))
    rospy.spin()
