#!/usr/bin/env python3
"""rostest node: the gripper bridge node drives a stand-in FR5 controller from std_msgs/Float64
widths, keeps running and reporting on ~status (and true on the fault topic) while the controller
is gone, and resends the newest width (after ActGripper 0 then 1) once it is back. Then the
simulator's controller emulator takes the port: the bridge commands it, and the width the
emulator measures comes back as the two finger joints on /fr5/gripper/joint_states.

This node plays the policy (the width on /fr5/gripper/command at 50 Hz) and the controller
(test/fr5_controller_standin.py's StandInController on 127.0.0.1:~port, the port the .test file
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
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, String

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the stand-in controller
from fr5_controller_standin import StandInController  # noqa: E402
from fr5_rl.config import load_robot_spec  # noqa: E402
from fr5_rl.sim.controller_emulator import ControllerEmulator, ControllerEmulatorSettings  # noqa: E402

NODE = "/fr5_gripper_bridge"


class Policy:
    """Publishes the current width at 50 Hz, as the policy node does."""

    def __init__(self):
        self.width = None
        self.publisher = rospy.Publisher("/fr5/gripper/command", Float64, queue_size=10)
        rospy.Timer(rospy.Duration(0.02), self.publish)

    def publish(self, _event):
        if self.width is not None:
            try:
                self.publisher.publish(Float64(data=self.width))
            except rospy.ROSException:  # the timer outlives the topic at shutdown: not a failure
                pass


class TestGripperBridgeNode(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.statuses = []  # (monotonic time, dict)
        self.errors = []  # (monotonic time, text)
        self.faults = []  # (monotonic time, bool) from the latched fault topic
        self.fingers = []  # (monotonic time, JointState)
        rospy.Subscriber(NODE + "/status", String, self.on_status, queue_size=50)
        rospy.Subscriber("/fr5/gripper/fault", Bool, self.on_fault, queue_size=50)
        rospy.Subscriber("/fr5/gripper/joint_states", JointState, self.on_fingers, queue_size=50)
        rospy.Subscriber("/rosout", Log, self.on_log, queue_size=200)

    def on_status(self, message):
        with self.lock:
            self.statuses.append((time.monotonic(), json.loads(message.data)))

    def on_fault(self, message):
        with self.lock:
            self.faults.append((time.monotonic(), message.data))

    def on_fingers(self, message):
        with self.lock:
            self.fingers.append((time.monotonic(), message))

    def fault_since(self, start):
        with self.lock:
            return [fault for t, fault in self.faults if t >= start]

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
        self.wait_for(lambda: self.faults, 5.0, "the latched fault topic")
        self.assertEqual([fault for _, fault in self.faults], [True])  # no controller yet

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
                             [("ActGripper", (1, 0)), ("ActGripper", (1, 1)), ("MoveGripper", (1, 50)),
                              ("MoveGripper", (1, 25))])
            self.assertEqual(self.faults[-1][1], False)

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
            self.assertEqual(self.fault_since(gone), [True])

            # Back on the same port: ActGripper again, then the newest width.
            controller.start()
            back = time.monotonic()
            recover = self.wait_for(lambda: controller.requests(since=back)[-1:] == [
                ("MoveGripper", (1, 75, 50, 50, 30000, 1))], 5.0, "the newest width to be resent")
            self.assertEqual(controller.requests(since=back)[:2], [("ActGripper", (1, 0)), ("ActGripper", (1, 1))])
            self.assertEqual(len(controller.requests(since=back)), 3)
            self.wait_for(lambda: self.fault_since(back) == [False], 2.0, "the fault to clear")
            self.wait_for(lambda: self.statuses[-1][1]["connected"] and self.statuses[-1][1]["last_sent"] == 75,
                          2.0, "~status to say connected again")
            print(f"controller lost: not connected on ~status after {detect:.2f} s; back: MoveGripper resent after "
                  f"{recover:.2f} s", flush=True)
        finally:
            controller.stop()
        self.check_fingers_from_the_emulator(port, policy)

    def check_fingers_from_the_emulator(self, port, policy):
        """The simulator's controller emulator on the same port: commanded by the bridge, read back
        as finger joint states (each finger at width / 2)."""
        settings = ControllerEmulatorSettings(gripper_index=1, move_gripper_args=[6, 10], invert_percent=False,
                                              position_zero_transient=0.1)
        emulator = ControllerEmulator(settings, port, time.monotonic)
        emulator.set_measured_width(0.01, moving=False)
        gone = time.monotonic()
        self.wait_for(lambda: self.fault_since(gone) == [True], 5.0, "the fault while no controller serves")
        emulator.start()
        try:
            back = time.monotonic()
            self.wait_for(lambda: emulator.commanded_width() is not None, 5.0, "the bridge to command the emulator")
            self.assertAlmostEqual(emulator.commanded_width(), 0.06)  # the policy's newest width
            self.assertEqual(emulator.requests()[:2], [("ActGripper", (1, 0)), ("ActGripper", (1, 1))])
            emulator.set_measured_width(0.056, moving=False)  # the simulated fingers, short of the target
            names = list(load_robot_spec().finger_joint_names)

            def fingers_at(width):
                with self.lock:
                    return [m for t, m in self.fingers if t >= back and list(m.name) == names
                            and all(abs(p - width / 2) < 1e-9 for p in m.position)]

            self.wait_for(lambda: fingers_at(0.056), 5.0, "finger joint states at 0.028 m each")
            message = fingers_at(0.056)[-1]
            self.assertGreater(message.header.stamp.to_sec(), 0.0)
            self.assertEqual(list(message.velocity), [])
            self.assertFalse(fingers_at(0.0), "the controller's transient 0 after the move was published")
            self.wait_for(lambda: self.fault_since(back) == [False], 2.0, "the fault to clear on the emulator")
            policy.width = 0.02
            self.wait_for(lambda: abs((emulator.commanded_width() or 0.0) - 0.02) < 1e-9, 5.0, "the emulator at 0.02 m")
            emulator.set_measured_width(0.02, moving=False)
            self.wait_for(lambda: fingers_at(0.02), 5.0, "finger joint states at 0.01 m each")
            print(f"emulator: {len(fingers_at(0.056)) + len(fingers_at(0.02))} finger joint states read back",
                  flush=True)
        finally:
            emulator.stop()


if __name__ == "__main__":
    rospy.init_node("test_gripper_bridge_node")
    rostest.rosrun("fr5_rl", "test_gripper_bridge_node", TestGripperBridgeNode)
