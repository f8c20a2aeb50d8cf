#!/usr/bin/env python3
"""rostest node for test/view_robot.test.

With launch/view_robot.launch running (joint_state_publisher at the home pose,
robot_state_publisher with urdf/fr5.urdf), the transform base_link -> tcp must appear
within 10 s and equal the tcp pose predicted by an FK written here from the current FR5's
published DH table as the vendor's v6 URDF lays it out (not from our URDF): within 1 mm and
1e-3 rad.
"""
import math
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros

PKG = "fr5_rl"
# The current FR5's joint origins in the parent frame: xyz (m), rpy (rad); every joint turns about z
# (d1 0.152, a2 -0.425, a3 -0.395, d4 0.102, d5 0.102; the flange face d6 = 0.1 beyond j6).
FR5_ORIGINS = [
    ((0, 0, 0), (0, 0, 0)),
    ((0, 0, 0.152), (1.570796, 0, 0)),
    ((-0.425, 0, 0), (0, 0, 0)),
    ((-0.395, 0, 0), (0, 0, 0)),
    ((0, 0, 0.102), (1.570796, 0, 0)),
    ((0, 0, 0.102), (-1.570796, 0, 0)),
]
HOME = (0.0, -1.570796, 1.570796, -1.570796, -1.570796, 0.0)   # rad, j1..j6
TCP_OFFSET = 0.1 + 0.17   # m along the j6 axis: the flange face, then the gripper's tcp beyond it
TIMEOUT = 10.0      # s


def rpy_matrix(r, p, y):
    """URDF roll-pitch-yaw rotation R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
            @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
            @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))


def tcp_pose(q):
    """(position 3, rotation 3x3) of the tcp in base_link for joint angles q (rad)."""
    t = np.eye(4)
    for (xyz, rpy), qi in zip(FR5_ORIGINS, q):
        a = np.eye(4)
        a[:3, :3] = rpy_matrix(*rpy)
        a[:3, 3] = xyz
        b = np.eye(4)
        b[:3, :3] = rpy_matrix(0, 0, qi)
        t = t @ a @ b
    return t[:3, 3] + TCP_OFFSET * t[:3, 2], t[:3, :3]


def quaternion_matrix(x, y, z, w):
    """3x3 rotation of a unit quaternion."""
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class TestViewRobotTf(unittest.TestCase):
    """base_link -> tcp from tf2 equals the FR5 FK at the home pose."""

    def test_tcp_at_home(self):
        buf = tf2_ros.Buffer()
        listener = tf2_ros.TransformListener(buf)  # noqa: F841 (keeps the subscription)
        start = rospy.get_time()
        ok = buf.can_transform("base_link", "tcp", rospy.Time(0), rospy.Duration(TIMEOUT))
        self.assertTrue(ok, "base_link -> tcp not available within %.0f s" % TIMEOUT)
        self.assertLessEqual(rospy.get_time() - start, TIMEOUT + 0.5)
        tf = buf.lookup_transform("base_link", "tcp", rospy.Time(0)).transform
        got_p = np.array([tf.translation.x, tf.translation.y, tf.translation.z])
        r = tf.rotation
        got_r = quaternion_matrix(r.x, r.y, r.z, r.w)
        want_p, want_r = tcp_pose(HOME)
        err = float(np.linalg.norm(got_p - want_p))
        self.assertLess(err, 1e-3, "tcp %s, expected %s (error %.2e m)" % (got_p, want_p, err))
        angle = math.acos(max(-1.0, min(1.0, (np.trace(got_r.T @ want_r) - 1.0) / 2.0)))
        self.assertLess(angle, 1e-3, "tcp orientation off by %.2e rad" % angle)
        # Home = gripper pointing straight down: the tcp z (approach) axis is base -z.
        self.assertAlmostEqual(float(got_r[2, 2]), -1.0, places=3)


if __name__ == "__main__":
    rospy.init_node("test_view_robot_tf")
    rostest.rosrun(PKG, "test_view_robot_tf", TestViewRobotTf)
