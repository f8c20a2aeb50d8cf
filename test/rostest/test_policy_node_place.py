#!/usr/bin/env python3
"""rostest node: a pick-and-place model's inputs on ROS: the object's shape and the place goal.

The robot and camera of test_policy_node_faults.py play the arm (``/joint_states``, tracking each
command exactly) and the camera (``/target_pose`` in ``camera_link``). This node publishes the
object's shape (``/target_shape``, shape_msgs/SolidPrimitive) and the goal (``/place_pose``,
geometry_msgs/PoseStamped in the ``table`` frame, which only tf2 relates to ``base_link``) phase by
phase. Without either, or with either unusable, no command may leave the node and it must say
why; with both, commands flow at 50 Hz.
"""
import unittest

import rospy
import rostest
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Log
from shape_msgs.msg import SolidPrimitive
from std_srvs.srv import SetBool

from fr5_rl.config import load_robot_spec
from test_policy_node_faults import SETTLE, RobotAndCamera


def goal_message(frame: str, x: float, y: float) -> PoseStamped:
    message = PoseStamped()
    message.header.frame_id = frame
    message.header.stamp = rospy.Time.now()
    message.pose.position.x, message.pose.position.y = x, y
    message.pose.orientation.z, message.pose.orientation.w = 0.38268343, 0.92387953  # 45 deg about z
    return message


class TestPolicyNodePlace(unittest.TestCase):
    def test_holds_without_shape_or_goal_and_runs_with_both(self):
        world = RobotAndCamera(load_robot_spec())
        said = []  # (time, text) of every log line of the policy node: waits are said at INFO
        rospy.Subscriber("/rosout", Log, lambda m: said.append((rospy.get_time(), m.msg))
                         if m.name.endswith("fr5_policy") else None, queue_size=200)
        shape_pub = rospy.Publisher("/target_shape", SolidPrimitive, queue_size=1, latch=True)
        goal_pub = rospy.Publisher("/place_pose", PoseStamped, queue_size=1, latch=True)

        def phase(duration):
            start = rospy.get_time()
            rospy.sleep(duration)
            end = rospy.get_time()
            return world.count_commands(start + SETTLE, end), end - start - SETTLE, [t for s, t in said if s >= start]

        # The node loads its model and makes its start move (~guard/go_to_start) before it needs
        # the object: wait until it says it has the arm.
        deadline = rospy.get_time() + 40.0
        while not any("policy has the arm" in text for _, text in said) and rospy.get_time() < deadline:
            rospy.sleep(0.1)
        count, _, texts = phase(1.5)
        self.assertEqual(count, 0, "commands without the object's shape")
        self.assertTrue(any("no object shape" in text for text in [t for _, t in said]), said[-3:])

        # A box given with its longer side along y (the node turns it a quarter): still no goal.
        shape_pub.publish(SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.04, 0.06, 0.05]))
        count, _, texts = phase(1.5)
        self.assertEqual(count, 0, "commands without a place goal")
        self.assertTrue(any("no place goal" in text for text in texts), texts[-3:])

        goal_pub.publish(goal_message("conveyor", 0.0, 0.1))  # a frame tf2 does not know
        count, _, texts = phase(1.5)
        self.assertEqual(count, 0, "commands with a goal tf2 cannot place")
        self.assertTrue(any("place goal unusable" in text and "conveyor" in text for text in texts), texts[-3:])

        goal_pub.publish(goal_message("table", -0.05, 0.1))  # base_link (-0.6, 0.1): in the region
        count, window, texts = phase(1.0)
        self.assertGreaterEqual(count, 0.6 * 50 * window, f"only {count} commands in {window:.2f} s with shape "
                                                          f"and goal ({texts[-3:]})")

        goal_pub.publish(goal_message("table", 1.0, 0.0))  # base_link x = +0.45: behind the arm
        count, _, texts = phase(1.5)
        self.assertEqual(count, 0, "commands toward a goal outside the placement region")
        self.assertTrue(any("placement region" in text for text in texts), texts[-3:])

        goal_pub.publish(goal_message("table", -0.05, 0.1))
        shape_pub.publish(SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[0.03]))
        count, _, texts = phase(1.5)
        self.assertEqual(count, 0, "commands for an object the policy does not know (a sphere)")
        self.assertTrue(any("object shape invalid" in text for text in texts), texts[-3:])

        # With no simulator to end the episode, the policy presses the object it never grasps toward
        # the table until the safety zone holds it: stand the arm back at home (paused, as an
        # operator would) before the last phase.
        enable = rospy.ServiceProxy("/fr5_policy/enable", SetBool)
        self.assertTrue(enable(False).success)
        with world.lock:
            world.positions = world.spec.home_joint_positions.copy()
        rospy.sleep(0.2)
        shape_pub.publish(SolidPrimitive(type=SolidPrimitive.CYLINDER, dimensions=[0.08, 0.025]))
        self.assertTrue(enable(True).success)
        count, window, texts = phase(1.5)
        self.assertGreaterEqual(count, 0.6 * 50 * window, f"a cylinder: only {count} commands ({texts[-3:]})")
        self.assertEqual(world.invalid, [], "a command outside the arm's limits was published")


if __name__ == "__main__":
    rospy.init_node("test_policy_node_place")
    rostest.rosrun("fr5_rl", "test_policy_node_place", TestPolicyNodePlace)
