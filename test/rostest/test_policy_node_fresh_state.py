#!/usr/bin/env python3
"""rostest node: each control period acts on a joint state no period before acted on.

This node plays a driver that publishes at the control rate on its own clock, as the FAIRINO
driver does (50 Hz), and a camera. It first learns the phase of the node's timer from the
commands (joint states at 100 Hz, where every tick finds a new one), then publishes one state
per period timed to arrive 6 ms before one tick and 6 ms after the next, in turn: what delivery
jitter does now and then when the two clocks lie close. A node that reads whatever state it has
at its tick acts on the previous period's state in every other period (and skips the next
state); this one, waiting for a new state (``~fresh_state_wait``), in none, and still commands
once per period. The 6 ms is the margin for the test's own error in finding the tick on a loaded
machine: without the wait every other period repeats while that error stays under 6 ms; with
it the late state still arrives inside the 15 ms wait.
"""
import math
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from fr5_rl.config import load_robot_spec
from fr5_rl.transforms import load_static_transforms, transform_in

PERIOD = 0.02  # s, the reach model's control period
JITTER = 0.006  # s before and after the ticks in turn


class Driver:
    """Joint states (following each command exactly) and the camera's target."""

    def __init__(self, spec):
        self.spec = spec
        self.lock = threading.Lock()
        self.positions = spec.home_joint_positions.copy()
        self.command_times = []  # wall s of each command's arrival
        self.timing = []  # the node's ~timing rows
        # In the air where the reach policy hovers (as test_policy_node_faults): commands keep flowing.
        camera_in_base = transform_in(load_static_transforms(), "base_link", "camera_link")
        self.target_in_camera = (np.linalg.inv(camera_in_base) @ np.array([-0.6, 0.0, 0.4, 1.0]))[:3]
        self.joint_pub = rospy.Publisher("/joint_states", JointState, queue_size=10, tcp_nodelay=True)
        self.target_pub = rospy.Publisher("/target_pose", PoseStamped, queue_size=10)
        rospy.Subscriber("/fr5/arm_controller/command", Float64MultiArray, self.on_command, queue_size=100,
                         tcp_nodelay=True)
        rospy.Subscriber("/fr5_policy/timing", Float64MultiArray, self.on_timing, queue_size=200)
        rospy.Timer(rospy.Duration(1.0 / 30.0), self.publish_target)

    def on_command(self, message):
        with self.lock:
            self.command_times.append(time.time())
            self.positions = np.asarray(message.data, dtype=float)  # a perfectly tracking arm

    def on_timing(self, message):
        with self.lock:
            self.timing.append(tuple(message.data))

    def publish_joints(self):
        message = JointState(name=list(self.spec.joint_names))
        with self.lock:
            message.position = self.positions.tolist()
        message.velocity = [0.0] * 6
        message.header.stamp = rospy.Time.now()
        self.joint_pub.publish(message)

    def publish_target(self, _event):
        message = PoseStamped()
        message.header.stamp = rospy.Time.now()
        message.header.frame_id = "camera_link"
        message.pose.position.x, message.pose.position.y, message.pose.position.z = self.target_in_camera
        message.pose.orientation.w = 1.0
        self.target_pub.publish(message)


def timer_phase(arrivals, compute_s):
    """The node's tick (wall s modulo the period) from its commands' arrival times: a command
    leaves ``compute_s`` after its tick (the node's own ~timing says how long a period takes)
    and now and then arrives some ms later still, so the densest 2 ms of the arrivals, less the
    compute time and a little for the transport, is the tick."""
    offsets = arrivals % PERIOD
    candidates = np.arange(0.0, PERIOD, 0.00025)
    counts = [(((offsets - start) % PERIOD) < 0.002).sum() for start in candidates]
    start = candidates[int(np.argmax(counts))]
    in_window = offsets[((offsets - start) % PERIOD) < 0.002]
    return (start + np.median((in_window - start) % PERIOD) - compute_s - 0.0003) % PERIOD


def sleep_until(wall_time):
    left = wall_time - time.time()
    if left > 0:
        time.sleep(left)


class TestFreshState(unittest.TestCase):
    def test_every_period_acts_on_a_new_state(self):
        driver = Driver(load_robot_spec())
        wait = rospy.get_param("/fr5_policy/fresh_state_wait")
        # 1. States at 100 Hz until commands flow; their arrival times give the timer's phase.
        deadline = time.time() + 45.0
        while time.time() < deadline and len(driver.command_times) < 150:
            driver.publish_joints()
            time.sleep(0.01)
        self.assertGreaterEqual(len(driver.command_times), 150, "the policy node never commanded")
        self.assertGreaterEqual(len(driver.timing), 20, "no ~timing from the policy node")
        with driver.lock:
            arrivals = np.array(driver.command_times[-100:])
            compute_s = float(np.median(np.array(driver.timing[-100:])[:, 2]))
        phase = timer_phase(arrivals, compute_s)

        # 2. One state a period, arriving JITTER before one tick and JITTER after the next.
        with driver.lock:
            driver.timing.clear()
            start_commands = len(driver.command_times)
        tick = (math.floor(time.time() / PERIOD) + 2) * PERIOD + phase
        start = time.time()
        for index in range(250):  # 5 s
            sleep_until(tick + (JITTER if index % 2 else -JITTER))
            driver.publish_joints()
            tick += PERIOD
        elapsed = time.time() - start
        with driver.lock:  # the periods after the last state repeat it, as they must: not counted
            rows = np.array(driver.timing[5:])
            commands = len(driver.command_times) - start_commands
        self.assertGreaterEqual(commands, 0.9 * elapsed / PERIOD, f"only {commands} commands in {elapsed:.1f} s")
        repeated = rows[:, 5].mean()
        ages = np.percentile(rows[:, 3] * 1000.0, [5, 25, 50, 75, 95]).round(1)
        rospy.loginfo(f"fresh_state_wait {wait} s: {repeated:.1%} repeated; state age at command p5-p95 {ages} ms; "
                      f"waited in {(rows[:, 4] > 0.0005).mean():.0%} of the periods")
        if wait > 0.0:
            self.assertLessEqual(repeated, 0.02, f"{repeated:.0%} of the periods acted on a state used before")
            self.assertGreater((rows[:, 4] > 0.0005).mean(), 0.1, "the node never waited for a state")
        else:  # the wait off: the test's timing must produce the repeats the wait prevents
            self.assertGreater(repeated, 0.15, f"only {repeated:.0%} repeated states without the wait")


if __name__ == "__main__":
    rospy.init_node("test_policy_node_fresh_state")
    rostest.rosrun("fr5_rl", "policy_node_fresh_state", TestFreshState)
