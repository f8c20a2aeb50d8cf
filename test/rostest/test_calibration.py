#!/usr/bin/env python3
"""rostest node: runs ``calibrate_camera.py`` against sim_policy.launch ``calibration:=true`` with a
hidden camera mount offset and checks the recovered base_link -> camera_link against the true
one (config/static_transforms.yaml's mount composed with ``~offset``).

Params: ~offset ("dx dy dz droll dpitch dyaw", m and rad, as the launch's sim_camera_offset),
~max_translation_error (m), ~max_rotation_error_deg.
"""
import math
import os
import subprocess
import tempfile
import unittest

import rospy
import rostest

from fr5_rl.perception.hand_eye import offset_transform, transform_error
from fr5_rl.transforms import load_static_transforms, transform_in


class TestCalibration(unittest.TestCase):
    def test_recovers_the_true_mount(self):
        offset = [float(v) for v in str(rospy.get_param("~offset")).split()]
        max_translation = float(rospy.get_param("~max_translation_error", 0.005))
        max_rotation = float(rospy.get_param("~max_rotation_error_deg", 0.5))
        configured = transform_in(load_static_transforms(), "base_link", "camera_link")
        true = configured @ offset_transform(offset)
        with tempfile.TemporaryDirectory() as scratch:
            out = os.path.join(scratch, "calibrated.yaml")
            tool = subprocess.run(["rosrun", "fr5_rl", "calibrate_camera.py", "--out", out], capture_output=True,
                                  text=True, timeout=220)
            rospy.loginfo(tool.stdout + tool.stderr)
            self.assertEqual(tool.returncode, 0, tool.stdout + tool.stderr)
            recovered = transform_in(load_static_transforms(out), "base_link", "camera_link")
        error_m, error_rad = transform_error(recovered, true)
        before_m, _ = transform_error(configured, true)
        self.assertGreater(before_m, 2 * max_translation, "the hidden offset is too small to test anything")
        self.assertLess(error_m, max_translation, f"translation error {error_m * 1e3:.1f} mm\n{tool.stdout}")
        self.assertLess(math.degrees(error_rad), max_rotation,
                        f"rotation error {math.degrees(error_rad):.2f} deg\n{tool.stdout}")


if __name__ == "__main__":
    rospy.init_node("test_calibration")
    rostest.rosrun("fr5_rl", "test_calibration", TestCalibration)
