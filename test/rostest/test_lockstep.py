#!/usr/bin/env python3
"""rostest node: lockstep outcomes through ROS equal gym's, episode by episode.

Params: ~model, ~episodes, ~seed (must match the launch). The gym episodes run here, in this
process, on the same seeds, with the policy node's own backend (``/fr5_policy/backend``); every
node of the launch runs on /clock, so this test keeps time on the wall clock.
"""
import json
import time
import unittest

import rospy
import rostest
from std_msgs.msg import String

from fr5_rl.config import package_root
from fr5_rl.deploy.policy import load_policy
from fr5_rl.training.evaluation import run_episodes


class TestLockstep(unittest.TestCase):
    def test_outcomes_equal_gym(self):
        model = rospy.get_param("~model")
        episodes, seed = int(rospy.get_param("~episodes")), int(rospy.get_param("~seed"))
        self.assertTrue(rospy.get_param("/use_sim_time"), "lockstep runs every node on /use_sim_time")
        outcomes = []
        rospy.Subscriber("/fr5_sim/episode_outcome", String, lambda m: outcomes.append(json.loads(m.data)),
                         queue_size=50)
        policy = load_policy(package_root() / model, rospy.get_param("/fr5_policy/backend"))
        gym = run_episodes(policy.task, policy.deployment_overrides(), lambda env: (policy.act, None), list(range(seed, seed + episodes)))
        deadline = time.monotonic() + 240.0
        while len(outcomes) < episodes and time.monotonic() < deadline and not rospy.is_shutdown():
            time.sleep(0.1)
        self.assertEqual(len(outcomes), episodes, f"only {len(outcomes)} lockstep episodes finished in time")
        ros = [(o["seed"], o["success"], o["failure"], o["steps"]) for o in outcomes]
        expected = [(r["seed"], r["success"], r["failure"], r["length"]) for r in gym]
        rospy.loginfo(f"lockstep: {ros}")
        self.assertEqual(ros, expected, "(seed, success, failure, steps) through ROS differ from gym")
        self.assertEqual([o["late_periods"] for o in outcomes], [0] * episodes,
                         "a period went without its command: the loop was not in lockstep")


if __name__ == "__main__":
    rospy.init_node("test_lockstep")
    rostest.rosrun("fr5_rl", "test_lockstep", TestLockstep)
