#!/usr/bin/env python3
"""rostest node: every transform of the node's files (``/static_transforms/config``: by default
config/static_transforms.yaml; a list, e.g. with config/camera_frames.yaml) is on /tf_static, in
one message (one StaticTransformBroadcaster call), and tf2 returns exactly the configured pose.
``~expected_config`` (optional) names the files to expect instead: another arm's cell, say, which
the node must have taken for the shipped file."""
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from tf2_msgs.msg import TFMessage

from fr5_rl.ros.static_transforms import config_files
from fr5_rl.transforms import load_transform_files, matrix_from_quaternion


class TestStaticTransforms(unittest.TestCase):
    def test_config_on_tf_static(self):
        expected = rospy.get_param("~expected_config", None) or rospy.get_param("/static_transforms/config",
                                                                                "static_transforms")
        entries = load_transform_files(config_files(expected))
        self.assertGreaterEqual(len(entries), 1)
        wanted = {(e["parent"], e["child"]) for e in entries}
        # /tf_static is latched and may have other publishers (the camera's own frames): one of the
        # messages, the node's, must carry every configured transform and nothing else.
        seen = []
        subscriber = rospy.Subscriber("/tf_static", TFMessage, lambda message: seen.append(
            {(t.header.frame_id, t.child_frame_id) for t in message.transforms}))
        deadline = rospy.Time.now() + rospy.Duration(20.0)
        while wanted not in seen and rospy.Time.now() < deadline and not rospy.is_shutdown():
            rospy.sleep(0.1)
        subscriber.unregister()
        self.assertIn(wanted, seen, "one /tf_static message must carry every configured transform")

        buffer = tf2_ros.Buffer()
        listener = tf2_ros.TransformListener(buffer)  # noqa: F841
        for entry in entries:
            transform = buffer.lookup_transform(entry["parent"], entry["child"], rospy.Time(0), rospy.Duration(10.0))
            t, r = transform.transform.translation, transform.transform.rotation
            got = matrix_from_quaternion([t.x, t.y, t.z], [r.x, r.y, r.z, r.w])
            np.testing.assert_allclose(got, entry["matrix"], atol=1e-6,
                                       err_msg=f"{entry['parent']} -> {entry['child']} differs from the config")


if __name__ == "__main__":
    rospy.init_node("test_static_transforms")
    rostest.rosrun("fr5_rl", "test_static_transforms", TestStaticTransforms)
