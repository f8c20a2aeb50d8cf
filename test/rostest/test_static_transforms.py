#!/usr/bin/env python3
"""rostest node: every transform of the node's files (``/static_transforms/config``: by default
config/static_transforms.yaml; a list, e.g. with config/camera_frames.yaml) is on /tf_static, in
one message (one StaticTransformBroadcaster call), and tf2 returns exactly the configured pose."""
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
        entries = load_transform_files(config_files(rospy.get_param("/static_transforms/config", "static_transforms")))
        self.assertGreaterEqual(len(entries), 1)
        message = rospy.wait_for_message("/tf_static", TFMessage, timeout=20.0)
        published = {(t.header.frame_id, t.child_frame_id) for t in message.transforms}
        wanted = {(e["parent"], e["child"]) for e in entries}
        self.assertEqual(published, wanted, "one /tf_static message must carry every configured transform")

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
