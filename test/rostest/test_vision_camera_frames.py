#!/usr/bin/env python3
"""rostest node: the simulated camera's frames, with ~publish_tf (the camera's) either way.

- /tf_static: camera_link -> camera_color_frame -> camera_color_optical_frame, each frame with
  exactly one parent, published by the camera node (publish_tf true) or by
  static_transforms_node.py (false), and no camera frame on /tf;
- tf2 gives base_link <- camera_color_optical_frame as config/static_transforms.yaml and
  config/camera_frames.yaml chain it, the pose the camera renders from;
- the detector's /target_pose, looked up in base_link, lies within a few mm of the simulator's
  true object of the same instant (ground truth on /fr5_sim/object).
"""
import unittest
from collections import defaultdict

import numpy as np
import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import PoseStamped
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from fr5_rl.config import load_yaml
from fr5_rl.transforms import load_transform_files, matrix_from_quaternion, transform_in

CAMERA = load_yaml("camera")
OPTICAL = CAMERA["frame_id"]
CHAIN = {OPTICAL: "camera_color_frame", "camera_color_frame": "camera_link", "camera_link": "base_link"}


def matrix(transform) -> np.ndarray:
    t, r = transform.translation, transform.rotation
    return matrix_from_quaternion((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))


class TestVisionCameraFrames(unittest.TestCase):
    def test_frames_and_detection_in_base_link(self):
        publish_tf = rospy.get_param("~publish_tf")
        # Every latched /tf_static publisher delivers its message to a new subscriber: all of them.
        parents, publishers, dynamic = defaultdict(set), {}, set()

        def on_static(message: TFMessage) -> None:
            for t in message.transforms:
                parents[t.child_frame_id].add(t.header.frame_id)
                publishers[t.child_frame_id] = message._connection_header["callerid"]

        rospy.Subscriber("/tf_static", TFMessage, on_static, queue_size=50)
        rospy.Subscriber("/tf", TFMessage, lambda m: dynamic.update(t.child_frame_id for t in m.transforms),
                         queue_size=50)
        rospy.wait_for_message("/camera/color/image_raw", rospy.AnyMsg, timeout=90.0)
        rospy.sleep(3.0)
        for child, parent in CHAIN.items():
            self.assertEqual(parents[child], {parent}, f"{child} must have exactly one parent, {parent}")
        self.assertFalse(dynamic & (set(CHAIN) | {"camera_aligned_depth_to_color_frame"}),
                         "camera frames must be static")
        expected = "/camera" if publish_tf else "/static_transforms"
        self.assertEqual(publishers[OPTICAL], expected, f"publish_tf {publish_tf}: the chain is {expected}'s")
        self.assertEqual(publishers["camera_link"], "/static_transforms", "the mount is the project's")

        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
        configured = transform_in(load_transform_files([CAMERA["mount_config"], CAMERA["frames_config"]]),
                                  "base_link", OPTICAL)
        looked_up = matrix(buffer.lookup_transform("base_link", OPTICAL, rospy.Time(0), rospy.Duration(10.0)).transform)
        np.testing.assert_allclose(looked_up, configured, atol=1e-6)

        truths = {}
        rospy.Subscriber("/fr5_sim/object", Marker, lambda m: truths.__setitem__(m.header.stamp.to_nsec(), m),
                         queue_size=200)
        errors = []
        deadline = rospy.get_time() + 60.0
        while len(errors) < 15 and rospy.get_time() < deadline:
            target = rospy.wait_for_message("/target_pose", PoseStamped, timeout=30.0)
            self.assertEqual(target.header.frame_id, OPTICAL)  # the arm never grasps here
            truth = truths.get(target.header.stamp.to_nsec())
            if truth is None:
                continue  # the ground truth of that instant arrived before this subscriber stood
            base_from_optical = matrix(buffer.lookup_transform("base_link", OPTICAL, target.header.stamp,
                                                               rospy.Duration(2.0)).transform)
            p, q = target.pose.position, truth.pose.position
            found = (base_from_optical @ np.array([p.x, p.y, p.z, 1.0]))[:3]
            errors.append(float(np.linalg.norm(found - [q.x, q.y, q.z])))
        rospy.loginfo(f"publish_tf {publish_tf}: detector error vs truth in base_link (m): {errors}")
        self.assertGreaterEqual(len(errors), 5, "too few detections matched to the ground truth of their instant")
        # A free object, the arm at its start pose: ~1.5 mm (docs/vision.md). A camera rendered
        # elsewhere than tf says (the 15 mm colour-sensor offset lost) fails both bounds.
        self.assertLess(float(np.median(errors)), 0.005)
        self.assertLess(max(errors), 0.02)


if __name__ == "__main__":
    rospy.init_node("test_vision_camera_frames")
    rostest.rosrun("fr5_rl", "test_vision_camera_frames", TestVisionCameraFrames)
