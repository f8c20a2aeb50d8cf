"""Messages the simulator node publishes: joint states by name, and rviz markers of the scene."""
from __future__ import annotations

from typing import Iterable, Sequence, Tuple

import rospy
from geometry_msgs.msg import Point
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker, MarkerArray

from ..objects import ObjectShape, quaternion_of_yaw
from ..sim.plant import JointStates, Pose, SceneDescription


def joint_state_message(states: JointStates, stamp: rospy.Time) -> JointState:
    """``sensor_msgs/JointState`` of the eight joints, by name."""
    message = JointState()
    message.header.stamp = stamp
    message.name = list(states.names)
    message.position = list(states.positions)
    message.velocity = list(states.velocities)
    return message


def _marker(kind: int, namespace: str, rgba: Sequence[float], frame_id: str, stamp: rospy.Time) -> Marker:
    marker = Marker(type=kind, action=Marker.ADD, ns=namespace, id=0)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.pose.orientation.w = 1.0
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = rgba
    return marker


def object_marker(scene: SceneDescription, object_pose: Pose, stamp: rospy.Time) -> Marker:
    """The object where it is now: shape, size (m) and pose in ``scene.frame_id``."""
    kind = Marker.CYLINDER if scene.object_shape == "cylinder" else Marker.CUBE
    obj = _marker(kind, "object", (0.85, 0.2, 0.15, 1.0), scene.frame_id, stamp)
    obj.scale.x, obj.scale.y, obj.scale.z = scene.object_size
    obj.pose.position.x, obj.pose.position.y, obj.pose.position.z = object_pose.position
    orientation = obj.pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = object_pose.quaternion
    return obj


def scene_markers(scene: SceneDescription, object_pose: Pose, tcp_path: Iterable[Tuple[float, float, float]],
                  stamp: rospy.Time) -> MarkerArray:
    """rviz markers: the table, the object where it is now, and the tcp's recent path."""
    frame = scene.frame_id
    table = _marker(Marker.CUBE, "table", (0.55, 0.42, 0.3, 1.0), frame, stamp)
    table.scale.x, table.scale.y, table.scale.z = scene.table_size
    table.pose.position.x, table.pose.position.y, table.pose.position.z = scene.table_center

    obj = object_marker(scene, object_pose, stamp)
    path = _marker(Marker.LINE_STRIP, "tcp_path", (0.1, 0.5, 1.0, 0.9), frame, stamp)
    path.scale.x = 0.004
    path.points = [Point(x=x, y=y, z=z) for x, y, z in tcp_path]
    markers = [table, obj, path]
    if scene.goal is not None:
        markers.append(goal_marker(scene, stamp))
    return MarkerArray(markers=markers)


def goal_marker(scene: SceneDescription, stamp: rospy.Time) -> Marker:
    """The object's outline where it is to be set down: its footprint at the goal, translucent green."""
    kind = Marker.CYLINDER if scene.object_shape == "cylinder" else Marker.CUBE
    goal = _marker(kind, "goal", (0.2, 0.85, 0.3, 0.45), scene.frame_id, stamp)
    goal.scale.x, goal.scale.y, _ = scene.object_size
    goal.scale.z = 0.004  # a footprint on the table
    x, y, yaw = scene.goal
    goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = x, y, scene.table_top_height + 0.002
    orientation = goal.pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = quaternion_of_yaw(yaw)
    return goal


def neighbour_markers(shapes: Sequence[ObjectShape], poses: Sequence[Pose], stamp: rospy.Time,
                      frame_id: str) -> MarkerArray:
    """A scene's other objects where they are now (namespace ``neighbours``, ids 0, 1, ...):
    each one's shape, size (m) and pose; a DELETEALL first, so that one taken off the table goes."""
    markers = [Marker(action=Marker.DELETEALL, ns="neighbours")]
    for number, (shape, pose) in enumerate(zip(shapes, poses)):
        item = _marker(Marker.CYLINDER if shape.kind == "cylinder" else Marker.CUBE, "neighbours",
                       (0.9, 0.55, 0.1, 1.0), frame_id, stamp)
        item.id = number
        item.scale.x, item.scale.y, item.scale.z = shape.size
        item.pose.position.x, item.pose.position.y, item.pose.position.z = pose.position
        orientation = item.pose.orientation
        orientation.x, orientation.y, orientation.z, orientation.w = pose.quaternion
        markers.append(item)
    return MarkerArray(markers=markers)
