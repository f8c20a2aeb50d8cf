"""Ghost robot node: the commands of a dry run (``policy_node.py _dry_run:=true``) drawn in rviz as
a second, see-through FR5 beside the measured one.

``robot_description.py --prefix PREFIX URDF`` gives the ghost's ``robot_description`` (every link
renamed ``<PREFIX><name>``). This node hangs that tree from the real base (``~base_frame -> <~prefix><root>``, identity, on /tf_static). A robot_state_publisher in
the ghost's namespace turns ``<ns>/joint_states`` (what the policy node would have commanded) into
the ghost's frames; rviz's RobotModel display reads ``<ns>/robot_description``.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped

from .params import exit_if_help_asked
from .robot_description import prefixed_description
from .lifetime import init_node


def main() -> int:
    exit_if_help_asked("ghost_robot_node.py", __doc__.split("\n\n")[0] + "\n\n~prefix (default ghost/), "
                       "~base_frame (default base_link)")
    init_node("ghost_robot")
    prefix = str(rospy.get_param("~prefix", "ghost/"))
    base_frame = str(rospy.get_param("~base_frame", "base_link"))
    try:
        _, root = prefixed_description(rospy.get_param("/robot_description"), prefix)
    except (KeyError, ValueError, ET.ParseError) as error:
        rospy.logfatal(f"ghost_robot: {error}")
        return 1
    anchor = TransformStamped()
    anchor.header.stamp = rospy.Time.now()
    anchor.header.frame_id, anchor.child_frame_id = base_frame, root
    anchor.transform.rotation.w = 1.0
    broadcaster = tf2_ros.StaticTransformBroadcaster()
    broadcaster.sendTransform([anchor])
    rospy.loginfo(f"ghost_robot: {root} drawn at {base_frame}")
    rospy.spin()
    return 0

