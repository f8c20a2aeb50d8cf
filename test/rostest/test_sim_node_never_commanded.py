#!/usr/bin/env python3
"""rostest node: a connected policy that never commands ends each episode as failure no_command
after the simulator's ~first_command_timeout, and the run reaches its last episode."""
import json
import time
import unittest

import rospy
import rostest
from std_msgs.msg import Float64MultiArray, String

TIMEOUT_S = 2.0  # sim_node_never_commanded.test's first_command_timeout


class TestSimNodeNeverCommanded(unittest.TestCase):
    def test_silent_policy_ends_each_episode(self):
        outcomes = []  # (monotonic s, outcome)
        rospy.Subscriber("/fr5_sim/episode_outcome", String,
                         lambda message: outcomes.append((time.monotonic(), json.loads(message.data))), queue_size=10)
        # Connected, as a policy node that holds is, and silent.
        publisher = rospy.Publisher("/fr5/arm_controller/command", Float64MultiArray, queue_size=1)
        started = time.monotonic()
        while len(outcomes) < 2 and time.monotonic() - started < 60.0 and not rospy.is_shutdown():
            time.sleep(0.1)
        self.assertEqual(len(outcomes), 2, f"the run stalled: {len(outcomes)} of 2 episodes ended in 60 s "
                                           f"({publisher.get_num_connections()} connections)")
        for _, outcome in outcomes:
            self.assertFalse(outcome["success"])
            self.assertEqual(outcome["failure"], "no_command")
        # Each episode waited its timeout, not less.
        self.assertGreaterEqual(outcomes[1][0] - outcomes[0][0], TIMEOUT_S - 0.1)


if __name__ == "__main__":
    rospy.init_node("test_sim_node_never_commanded")
    rostest.rosrun("fr5_rl", "test_sim_node_never_commanded", TestSimNodeNeverCommanded)
