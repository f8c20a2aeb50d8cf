#!/usr/bin/env python3
"""rostest node: the simulator keeps publishing joint states while the policy node's ~reset is
in flight, and (episode_start reset) does not obey commands until it has answered.

This node plays the policy node: it offers /fr5_policy/reset, which answers after
``RESET_DELAY_S``, and it asks the simulator for new episodes through /fr5_sim/reset.
"""
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger, TriggerResponse

RESET_DELAY_S = 1.5
PUBLISH_PERIOD_S = 1.0 / 200.0  # config/sim_node.yaml publish_rate


class TestSimNodeSlowPolicy(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.arrivals = []  # (monotonic s, arm positions)
        self.resets = []  # (monotonic s of the call, of the answer)
        self.in_flight = 0
        rospy.Service("/fr5_policy/reset", Trigger, self.on_reset)
        self.command_pub = rospy.Publisher("/fr5/arm_controller/command", Float64MultiArray, queue_size=1)
        rospy.Subscriber("/joint_states", JointState, self.on_state, queue_size=100, tcp_nodelay=True)
        rospy.wait_for_service("/fr5_sim/reset", timeout=60.0)
        self.sim_reset = rospy.ServiceProxy("/fr5_sim/reset", Trigger)
        deadline = time.monotonic() + 30.0
        while not self.arrivals and time.monotonic() < deadline:
            time.sleep(0.05)
        self.assertTrue(self.arrivals, "no /joint_states from the simulator in 30 s")
        while self.in_flight and time.monotonic() < deadline:  # the first episode's reset
            time.sleep(0.05)

    def on_reset(self, _request):
        called = time.monotonic()
        with self.lock:
            self.in_flight += 1
        time.sleep(RESET_DELAY_S)
        with self.lock:
            self.resets.append((called, time.monotonic()))
            self.in_flight -= 1
        return TriggerResponse(success=True, message="slow on purpose")

    def on_state(self, message):
        with self.lock:
            self.arrivals.append((time.monotonic(), np.array(message.position[:6])))

    def test_states_flow_and_commands_wait_for_the_policy(self):
        with self.lock:
            before = len(self.resets)
        self.sim_reset()
        deadline = time.monotonic() + RESET_DELAY_S + 10.0
        with self.lock:
            away = self.arrivals[-1][1] + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
        # Until its reset has answered, the policy node sends a command far from home.
        while time.monotonic() < deadline:
            with self.lock:
                if len(self.resets) > before:
                    break
            self.command_pub.publish(Float64MultiArray(data=away.tolist()))
            time.sleep(0.02)
        with self.lock:
            self.assertGreater(len(self.resets), before, "the simulator never called the policy node's ~reset")
            called, answered = self.resets[-1]
            during = [(t, q) for t, q in self.arrivals if called <= t <= answered]
        gaps = np.diff([t for t, _ in during])
        self.assertGreater(len(during), 0.5 * RESET_DELAY_S / PUBLISH_PERIOD_S,
                           f"only {len(during)} joint states in the {RESET_DELAY_S} s the policy's reset took")
        self.assertLess(float(gaps.max()), 0.1, f"joint states stopped for {gaps.max():.3f} s during the reset")
        if rospy.get_param("~episode_start") == "reset":
            moved = max(float(np.abs(q - during[0][1]).max()) for _, q in during)
            self.assertLess(moved, 0.01, f"the arm moved {moved:.3f} rad on a command sent before the policy "
                                         "node answered its reset")


if __name__ == "__main__":
    rospy.init_node("slow_policy")
    rostest.rosrun("fr5_rl", "sim_node_slow_policy", TestSimNodeSlowPolicy)
