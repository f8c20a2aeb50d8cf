#!/usr/bin/env python3
"""rostest node: the gripper bridge node drives a stand-in FR5 controller from std_msgs/Float64
widths, keeps running and reporting on ~status while the controller is gone, and resends the
newest width (after ActGripper) once it is back.

This node plays the policy (the width on /fr5/gripper/command at 50 Hz) and the controller
(test/test_gripper_bridge.py's StandInController on 127.0.0.1:~port, the port the .test file
gives the bridge's ~controller_url).
"""
import json
import sys
import threading
import time
import unittest
from pathlib import Path

import rospy
import rostest
from rosgraph_msgs.msg import Log
from std_msgs.msg import Float64, String

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the stand-in controller
from test_gripper_bridge import StandInController  # noqa: E402

NODE = "/fr5_gripper_bridge"


class Policy:
    """Publishes the current width at 50 Hz, as the policy node does."""

    def __init__(self):
        self.width = None
        self.publisher = rospy.Publisher("/fr5/gripper/command", Float64, queue_size=10)
        rospy.Timer(rospy.Duration(0.02), self.publish)

    def publish(self, _event):
        if self.width is not None:
            self.publisher.publish(Float64(data=self.width))


class TestGripperBridgeNode(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.statuses = []  # (monotonic time, dict)
        self.errors = []  # (monotonic time, text)
        rospy.Subscriber(NODE + "/status", String, self.on_status, queue_size=50)
        rospy.Subscriber("/rosout", Log, self.on_log, queue_size=200)

    def on_status(self, message):
        with self.lock:
            self.statuses.append((time.monotonic(), json.loads(message.data)))

    def on_log(self, message):
        if message.name == NODE and message.level >= Log.ERROR:
            with self.lock:
                self.errors.append((time.monotonic(), message.msg))

    def since(self, start):
        with self.lock:
            return [status for t, status in self.statuses if t >= start]

    def wait_for(self, predicate, timeout, what):
        start = time.monotonic()
        while not predicate():
            if time.monotonic() - start > timeout or rospy.is_shutdown():
                self.fail(f"timed out after {timeout} s waiting for {what}; last status: "
                          f"{self.statuses[-1][1] if self.statuses else None}")
            time.sleep(0.01)
        return time.monotonic() - start

    def test_drives_the_controller_and_survives_its_loss(self):
        port = int(rospy.get_param("~port"))
        policy = Policy()
        # The node is up before any controller: it must report that, not die.
        self.wait_for(lambda: self.statuses, 30.0, "the first ~status")
        self.assertFalse(self.statuses[-1][1]["connected"])

        controller = StandInController(port)
        try:
            self.wait_for(lambda: self.since(time.monotonic() - 0.05) and self.statuses[-1][1]["connected"],
                          5.0, "the bridge to connect to the stand-in")
            policy.width = 0.04
            self.wait_for(lambda: ("MoveGripper", (1, 50, 50, 50, 30000, 1)) in controller.requests(), 5.0,
                          "MoveGripper to 50 %")
            policy.width = 0.02
            self.wait_for(lambda: controller.requests()[-1:] == [("MoveGripper", (1, 25, 50, 50, 30000, 1))], 5.0,
                          "MoveGripper to 25 %")
            time.sleep(0.3)
            # 50 Hz of the same width is one call per change, and ActGripper came first, once.
            self.assertEqual([(m, a[:2]) for m, a in controller.requests()],
                             [("ActGripper", (1, 1)), ("MoveGripper", (1, 50)), ("MoveGripper", (1, 25))])

            # A NaN width is dropped with an error; nothing is sent for it.
            count = len(controller.requests())
            policy.width = float("nan")
            self.wait_for(lambda: any("non-finite" in text for _, text in self.errors), 5.0, "the NaN error")
            time.sleep(0.3)
            self.assertEqual(len(controller.requests()), count)
            policy.width = 0.02

            # The controller goes away mid-run.
            controller.stop()
            gone = time.monotonic()
            policy.width = 0.06
            detect = self.wait_for(lambda: any(not s["connected"] for s in self.since(gone)), 5.0,
                                   "~status to say not connected")
            time.sleep(1.5)
            during = self.since(gone + detect + 0.05)
            self.assertGreaterEqual(len(during), 10, "~status stopped flowing while the controller was away")
            self.assertTrue(all(not s["connected"] and s["last_error"] for s in during), during[-1])
            self.assertGreater(during[-1]["failures"], during[0]["failures"], "no retries while away")
            self.assertTrue(any("unreachable" in text for t, text in self.errors if t >= gone))

            # Back on the same port: ActGripper again, then the newest width.
            controller.start()
            back = time.monotonic()
            recover = self.wait_for(lambda: controller.requests(since=back)[-1:] == [
                ("MoveGripper", (1, 75, 50, 50, 30000, 1))], 5.0, "the newest width to be resent")
            self.assertEqual([m for m, _ in controller.requests(since=back)], ["ActGripper", "MoveGripper"])
            self.wait_for(lambda: self.statuses[-1][1]["connected"] and self.statuses[-1][1]["last_sent"] == 75,
                          2.0, "~status to say connected again")
            print(f"controller lost: not connected on ~status after {detect:.2f} s; back: MoveGripper resent after "
                  f"{recover:.2f} s", flush=True)
        finally:
            controller.stop()


if __name__ == "__main__":
    rospy.init_node("test_gripper_bridge_node")
    rostest.rosrun("fr5_rl", "test_gripper_bridge_node", TestGripperBridgeNode)
