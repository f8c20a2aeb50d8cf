"""Static transforms node: config/static_transforms.yaml on /tf_static, in one call.

``tf2_ros.StaticTransformBroadcaster.sendTransform`` replaces what the node published before,
so every transform goes out in a single call. Parameters:

- ``~config`` (str): path of the YAML file; default: the package's config/static_transforms.yaml
"""
from __future__ import annotations

import sys

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped

from ..config import ConfigError
from ..transforms import load_static_transforms, quaternion_from_matrix
from .params import exit_if_help_asked


def to_messages(entries, stamp) -> list:
    """TransformStamped messages (parent -> child) for the configured entries."""
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


def main() -> None:
    exit_if_help_asked("static_transforms_node.py", __doc__.split("\n\n")[0] + "\n\n~config: a path or a name in "
                       "config/ (default: static_transforms)")
    rospy.init_node("static_transforms")
    path = rospy.get_param("~config", "static_transforms")
    try:
        entries = load_static_transforms(path)
    except ConfigError as error:
        rospy.logfatal(f"static_transforms: {error}")
        sys.exit(1)
    broadcaster = tf2_ros.StaticTransformBroadcaster()
    broadcaster.sendTransform(to_messages(entries, rospy.Time.now()))
    rospy.loginfo("published %d static transforms: %s", len(entries),
                  ", ".join(f"{e['parent']}->{e['child']}" for e in entries))
    rospy.spin()
