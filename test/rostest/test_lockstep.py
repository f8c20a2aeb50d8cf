#!/usr/bin/env python3
"""rostest node: lockstep outcomes through ROS equal gym's, episode by episode.

Params: ~model, ~episodes, ~seed (must match the launch). The gym episodes run here, in this
process, on the same seeds, with the policy node's own backend (``/fr5_policy/backend``); every
node of the launch runs on /clock, so this test keeps time on the wall clock. The simulator's
outcomes are read from its ``~outcome_log`` (relative to the directory both nodes run in), which it
writes before it can exit after its last episode.
"""
import json
import time
import unittest
from pathlib import Path

import rospy
import rostest

from fr5_rl.config import package_root
from fr5_rl.deploy.policy import load_policy
from fr5_rl.training.evaluation import run_episodes


class TestLockstep(unittest.TestCase):
    def test_outcomes_equal_gym(self):
        model = rospy.get_param("~model")
        episodes, seed = int(rospy.get_param("~episodes")), int(rospy.get_param("~seed"))
        self.assertTrue(rospy.get_param("/use_sim_time"), "lockstep runs every node on /use_sim_time")
        log = Path(rospy.get_param("/fr5_sim/outcome_log"))
        self.addCleanup(log.unlink, missing_ok=True)

        def read_outcomes():  # whole lines only: the simulator may be writing the next one
            return [json.loads(line) for line in log.read_text().split("\n")[:-1]] if log.is_file() else []

        policy = load_policy(package_root() / model, rospy.get_param("/fr5_policy/backend"))
        gym = run_episodes(policy.task, policy.deployment_overrides(), lambda env: (policy.act, None), list(range(seed, seed + episodes)))
        deadline = time.monotonic() + 240.0
        # Shut down (the simulator exits after its last episode): the log holds what it finished.
        while len(read_outcomes()) < episodes and time.monotonic() < deadline and not rospy.is_shutdown():
            time.sleep(0.1)
        outcomes = read_outcomes()
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
