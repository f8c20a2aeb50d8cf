#!/usr/bin/env python3
"""rostest node: the vision chain's messages. The camera publishes rgb8 colour, 16UC1 depth and
a CameraInfo of one size, stamped alike, in the optical frame; the detector's /target_pose is in
that frame (or the tcp frame, for an object held in the gripper) with an image's stamp, and
lies within 5 mm of the simulator's true object centre of the same instant (ground truth on
/fr5_sim/object). The optical frame has one parent, camera_color_frame (the camera's own chain,
as realsense2_camera publishes it; the project publishes only the mount)."""
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from fr5_rl.transforms import matrix_from_quaternion


class TestVisionTopics(unittest.TestCase):
    def test_camera_and_detector_messages(self):
        color = rospy.wait_for_message("/camera/color/image_raw", Image, timeout=60.0)
        depth = rospy.wait_for_message("/camera/aligned_depth_to_color/image_raw", Image, timeout=10.0)
        info = rospy.wait_for_message("/camera/color/camera_info", CameraInfo, timeout=10.0)
        self.assertEqual((color.encoding, depth.encoding), ("rgb8", "16UC1"))
        self.assertEqual({(m.width, m.height) for m in (color, depth, info)}, {(info.width, info.height)})
        self.assertEqual({m.header.frame_id for m in (color, depth, info)}, {"camera_color_optical_frame"})
        self.assertGreater(info.K[0], 0.0)

        # Every latched /tf_static publisher delivers its transforms to a new subscriber.
        parents = {}
        rospy.Subscriber("/tf_static", TFMessage, lambda m: [parents.setdefault(t.child_frame_id, set()).add(
            t.header.frame_id) for t in m.transforms], queue_size=50)
        rospy.sleep(2.0)
        self.assertEqual(parents.get("camera_color_optical_frame"), {"camera_color_frame"})
        self.assertEqual(parents.get("camera_color_frame"), {"camera_link"})

        truths = {}
        rospy.Subscriber("/fr5_sim/object", Marker, lambda m: truths.__setitem__(m.header.stamp.to_nsec(), m),
                         queue_size=200)
        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
        errors = []
        deadline = rospy.get_time() + 60.0
        while len(errors) < 10 and rospy.get_time() < deadline:
            target = rospy.wait_for_message("/target_pose", PoseStamped, timeout=30.0)
            # An object held in the gripper is published in the tcp frame (it moves with it).
            self.assertIn(target.header.frame_id, ("camera_color_optical_frame", "tcp"))
            if target.header.frame_id != "camera_color_optical_frame":
                continue
            truth = truths.get(target.header.stamp.to_nsec())
            if truth is None:
                continue  # the ground truth of that instant arrived before this subscriber stood
            t = buffer.lookup_transform("base_link", target.header.frame_id, rospy.Time(0), rospy.Duration(5.0))
            tr, r = t.transform.translation, t.transform.rotation
            base_from_optical = matrix_from_quaternion((tr.x, tr.y, tr.z), (r.x, r.y, r.z, r.w))
            p = target.pose.position
            found = (base_from_optical @ np.array([p.x, p.y, p.z, 1.0]))[:3]
            q = truth.pose.position
            # Only objects the gripper cannot hide or have nudged: the tcp 10 cm or more away.
            # Near it the tracker republishes the last sighting (stamped with the new image), and
            # a cup the fingers brushed has moved by then: that is tracking, not detection.
            try:
                tcp = buffer.lookup_transform("base_link", "tcp", target.header.stamp, rospy.Duration(0.5)).transform.translation
            except (tf2_ros.LookupException, tf2_ros.ExtrapolationException, tf2_ros.ConnectivityException):
                continue
            if np.linalg.norm([tcp.x - q.x, tcp.y - q.y, tcp.z - q.z]) < 0.10:
                continue
            errors.append(float(np.linalg.norm(found - [q.x, q.y, q.z])))
        self.assertGreaterEqual(len(errors), 5, "too few detections matched to the ground truth of their instant")
        rospy.loginfo(f"detector error vs truth (m): {errors}")
        # A free object within 5 mm at the median (tools/bench/vision.py measures p95 1.75 mm with
        # the arm at its start pose; here the image may be one frame older than the truth's stamp).
        self.assertLess(float(np.median(errors)), 0.005)

    def test_every_object_is_reported_with_its_kind(self):
        # detector_node.py ~objects: the one object of the scene (the simulator's cup), in the
        # table frame with an image's stamp, its kind and centre those of the ground truth.
        from fr5_rl.msg import DetectedObjects

        truths = {}
        rospy.Subscriber("/fr5_sim/object", Marker, lambda m: truths.__setitem__(m.header.stamp.to_nsec(), m),
                         queue_size=200)
        matched, ids, errors = 0, set(), []
        deadline = rospy.get_time() + 60.0
        while matched < 5 and rospy.get_time() < deadline:
            report = rospy.wait_for_message("/detector/objects", DetectedObjects, timeout=30.0)
            self.assertEqual(report.header.frame_id, "base_link")
            truth = truths.get(report.header.stamp.to_nsec())  # the image's stamp: the instant it shows
            if truth is None or len(report.objects) != 1:
                continue  # before the truth of that instant came, or the arm over the object
            found = report.objects[0]
            kinds = ("cylinder",) if truth.type == Marker.CYLINDER else ("square box", "rectangular box")
            self.assertIn(found.kind, kinds)
            self.assertGreater(found.id, 0)
            ids.add(found.id)
            p, q = found.pose.position, truth.pose.position
            error = float(np.linalg.norm([p.x - q.x, p.y - q.y, p.z - q.z]))
            self.assertLess(error, 0.01)
            errors.append(error)
            matched += 1
        self.assertGreaterEqual(matched, 5, "too few reports matched to the ground truth of their instant")
        rospy.loginfo(f"every-object report's error vs truth (m): {errors}")
        # One object standing still: one id (the policy's arm may hide it; a new episode places a
        # new object, which may take a new id).
        self.assertLessEqual(len(ids), 2, ids)


if __name__ == "__main__":
    rospy.init_node("test_vision_topics")
    rostest.rosrun("fr5_rl", "test_vision_topics", TestVisionTopics)
