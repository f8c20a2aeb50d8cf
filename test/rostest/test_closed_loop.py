#!/usr/bin/env python3
"""rostest node: counts the simulator's episode outcomes and checks the success rate.

Params: ~episodes (how many to watch), ~min_success_rate, ~command_topic, and optionally
~joint_states_topic with ~joint_names (the exact set of names every message must carry) and
~no_warnings (a nominal run: no node may log a WARN or worse on /rosout while it lasts). Every
command seen on the way must be a valid command (6 finite values inside the joint limits of the
arm the launch describes: /robot_description names it).
"""
import json
import unittest

import numpy as np
import rospy
import rostest
from sensor_msgs.msg import JointState
from rosgraph_msgs.msg import Log
from std_msgs.msg import Float64MultiArray, String

from fr5_rl.config import load_robot_spec
from fr5_rl.ros.robot_description import robot_name

ROSPY_HANDSHAKE_HANG_UP = "Inbound TCP/IP connection failed: connection from sender terminated before handshake"


class TestClosedLoop(unittest.TestCase):
    def test_success_rate(self):
        episodes = int(rospy.get_param("~episodes", 10))
        min_rate = float(rospy.get_param("~min_success_rate", 0.9))
        spec = load_robot_spec(robot_name(rospy.get_param("/robot_description")))
        outcomes, bad_commands, commands = [], [], [0]

        def on_outcome(message):
            outcomes.append(json.loads(message.data))

        def on_command(message):
            commands[0] += 1
            values = np.asarray(message.data)
            if values.shape != (6,) or not np.isfinite(values).all() or (values < spec.lower_limits).any() \
                    or (values > spec.upper_limits).any():
                bad_commands.append(list(message.data))

        rospy.Subscriber("/fr5_sim/episode_outcome", String, on_outcome, queue_size=50)
        command_topic = rospy.get_param("~command_topic", "/fr5/arm_controller/command")
        rospy.Subscriber(command_topic, Float64MultiArray, on_command, queue_size=50)
        expected_names = set(rospy.get_param("~joint_names", []))
        names_seen = set()
        if expected_names:
            rospy.Subscriber(rospy.get_param("~joint_states_topic"), JointState,
                             lambda m: names_seen.add(tuple(sorted(m.name))), queue_size=50)
        warnings = []
        if rospy.get_param("~no_warnings", False):
            # rospy's own transport logs a peer that hung up mid-handshake (a node of the launch
            # starting or stopping a connection) as a warning: the ROS plumbing's, not ours.
            rospy.Subscriber("/rosout", Log, lambda m: warnings.append(f"[{m.name}] {m.msg}")
                             if m.level >= Log.WARN and not m.msg.startswith(ROSPY_HANDSHAKE_HANG_UP) else None,
                             queue_size=200)
        deadline = rospy.get_time() + 220.0
        while len(outcomes) < episodes and rospy.get_time() < deadline and not rospy.is_shutdown():
            rospy.sleep(0.2)
        watched = outcomes[:episodes]
        self.assertEqual(len(watched), episodes, f"only {len(outcomes)} episodes finished in time")
        successes = sum(o["success"] for o in watched)
        rospy.loginfo(f"closed loop: {successes}/{episodes} successes: {watched}")
        self.assertGreater(commands[0], 0, "the policy node never commanded the arm")
        self.assertEqual(bad_commands, [], "invalid commands were published")
        if expected_names:
            self.assertEqual(names_seen, {tuple(sorted(expected_names))}, "joint_states carried other joints")
        self.assertEqual(warnings, [], "a nominal run logged warnings or errors")
        self.assertGreaterEqual(successes / episodes, min_rate,
                                f"success {successes}/{episodes} below {min_rate:.0%}: {watched}")


if __name__ == "__main__":
    rospy.init_node("test_closed_loop")
    rostest.rosrun("fr5_rl", "test_closed_loop", TestClosedLoop)
