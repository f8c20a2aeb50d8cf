#!/usr/bin/env python3
"""rostest node: clearing a table through the whole rehearsal (sim_policy_clearing.test). The
detector reports every object of the scene within 5 mm of where the simulator has it, with its
kind, and names the one it gives the policy; its ~select refuses a rule that cannot choose; the
scene is cleared with one outcome per object, in order, at least one of them placed."""
import json
import threading
import unittest

import numpy as np
import rospy
import rostest
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from fr5_rl.msg import DetectedObjects
from fr5_rl.srv import SelectObject


class TestClearing(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.lock = threading.Lock()
        cls.truths = {}  # stamp (ns) -> [(kind, position)] of every object then
        cls.objects_at_start = None
        cls.outcomes = []
        cls.target = {}

        def on_target(message):
            with cls.lock:
                cls.target[message.header.stamp.to_nsec()] = message

        def on_neighbours(message):
            with cls.lock:
                stamp = next((m.header.stamp.to_nsec() for m in message.markers if m.action == Marker.ADD), None)
                target = cls.target.get(stamp)
                if target is None:
                    return
                # Before the first episode the episode's object waits off the table (z -10 m).
                markers = [m for m in [target] + list(message.markers)
                           if m.action == Marker.ADD and m.pose.position.z > -1.0]
                cls.truths[stamp] = [(m.type, np.array([m.pose.position.x, m.pose.position.y])) for m in markers]
                if cls.objects_at_start is None:
                    cls.objects_at_start = len(markers)

        rospy.Subscriber("/fr5_sim/object", Marker, on_target, queue_size=200)
        rospy.Subscriber("/fr5_sim/neighbours", MarkerArray, on_neighbours, queue_size=200)
        rospy.Subscriber("/fr5_sim/episode_outcome", String,
                         lambda message: cls.outcomes.append(json.loads(message.data)), queue_size=50)

    def test_1_every_object_is_reported_and_the_chosen_one_named(self):
        errors, deadline = [], rospy.get_time() + 90.0
        while len(errors) < 10 and rospy.get_time() < deadline:
            report = rospy.wait_for_message("/detector/objects", DetectedObjects, timeout=60.0)
            self.assertEqual(report.header.frame_id, "base_link")
            with self.lock:
                truth = self.truths.get(report.header.stamp.to_nsec())
            if truth is None or len(report.objects) < 2 or report.chosen_id == 0:
                continue  # the truth of that instant is not in yet, or the arm hides all but one
            self.assertIn(report.chosen_id, [item.id for item in report.objects])
            for item in report.objects:
                found = np.array([item.pose.position.x, item.pose.position.y])
                errors.append(min(np.linalg.norm(found - position) for _, position in truth))
                self.assertIn(item.kind, ("cylinder", "square box", "rectangular box"))
        self.assertGreaterEqual(len(errors), 10, "the detector reported fewer than two objects with a chosen one")
        rospy.loginfo(f"clearing: {len(errors)} objects reported, error to the truth max {max(errors) * 1000:.1f} mm")
        self.assertLess(max(errors), 0.005)

    def test_2_select_refuses_a_rule_that_cannot_choose(self):
        rospy.wait_for_service("/detector/select", timeout=30.0)
        select = rospy.ServiceProxy("/detector/select", SelectObject)
        for request in ({"rule": "farthest"}, {"rule": "kind", "kind": "sphere"}, {"rule": "id", "id": 0}):
            answer = select(**request)
            self.assertFalse(answer.success, request)
            self.assertTrue(answer.message, request)
        answer = select(rule="nearest")  # config/clearing.yaml's rule, in force
        self.assertTrue(answer.success and "unchanged" in answer.message, answer.message)

    def test_3_the_scene_is_cleared_one_outcome_per_object(self):
        deadline = rospy.get_time() + 240.0
        while rospy.get_time() < deadline and (self.objects_at_start is None
                                               or len(self.outcomes) < self.objects_at_start):
            rospy.sleep(0.5)
        self.assertIsNotNone(self.objects_at_start)
        outcomes = sorted(self.outcomes, key=lambda record: record["episode"])
        self.assertEqual(len(outcomes), self.objects_at_start, outcomes)
        self.assertEqual([record["scene"] for record in outcomes], [0] * len(outcomes))
        self.assertEqual([record["object_in_scene"] for record in outcomes], list(range(len(outcomes))))
        placed = sum(record["success"] for record in outcomes)
        rospy.loginfo(f"clearing: {placed}/{len(outcomes)} placed: {[record['failure'] for record in outcomes]}")
        self.assertGreaterEqual(placed, 1, outcomes)


if __name__ == "__main__":
    rospy.init_node("test_clearing_rehearsal")
    rostest.rosrun("fr5_rl", "test_clearing_rehearsal", TestClearing)
