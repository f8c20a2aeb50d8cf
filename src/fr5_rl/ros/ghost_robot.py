"""Ghost robot node: the commands of a dry run (``policy_node.py _dry_run:=true``) drawn in rviz as
a second, see-through FR5 beside the measured one.

``ghost_robot_node.py --description URDF PREFIX`` prints the URDF with every
link renamed ``<PREFIX><name>`` (a launch file's ``<param command=...>`` sets the ghost's
``robot_description`` with it, before any node starts). As a node it hangs that tree from the
real base (``~base_frame -> <~prefix><root>``, identity, on /tf_static). A robot_state_publisher in
the ghost's namespace turns ``<ns>/joint_states`` (what the policy node would have commanded) into
the ghost's frames; rviz's RobotModel display reads ``<ns>/robot_description``.
"""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped

from .params import exit_if_help_asked


def prefixed_description(urdf: str, prefix: str) -> tuple:
    """``urdf`` with every link name prefixed, and the name of its root link.

    :raises ValueError: not a URDF, or it has no single root link.
    """
    robot = ET.fromstring(urdf)
    if robot.tag != "robot":
        raise ValueError("robot_description is not a URDF <robot>")
    children = {joint.find("child").get("link") for joint in robot.findall("joint")}
    roots = [link.get("name") for link in robot.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"robot_description has {len(roots)} root links, a tree has one")
    for link in robot.findall("link"):
        link.set("name", prefix + link.get("name"))
    for joint in robot.findall("joint"):  # joints keep their names: the ghost's joint states are the arm's
        for end in ("parent", "child"):
            element = joint.find(end)
            element.set("link", prefix + element.get("link"))
    return ET.tostring(robot, encoding="unicode"), prefix + roots[0]


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "--description":
        with open(sys.argv[2], encoding="utf-8") as urdf:
            print(prefixed_description(urdf.read(), sys.argv[3])[0])
        return 0
    exit_if_help_asked("ghost_robot_node.py", __doc__.split("\n\n")[0] + "\n\n--description URDF PREFIX: print the "
                       "prefixed URDF. As a node: ~prefix (default ghost/), ~base_frame (default base_link)")
    rospy.init_node("ghost_robot")
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

