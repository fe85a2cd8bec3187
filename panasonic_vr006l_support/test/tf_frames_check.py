#!/usr/bin/python3
"""rostest node: every expected frame becomes available on /tf (from base_link) within ~timeout."""
import sys
import unittest

import rospy
import rostest
import tf2_ros


class TfFrames(unittest.TestCase):
    def test_all_frames_on_tf(self):
        timeout = rospy.get_param("~timeout", 10.0)
        frames = rospy.get_param("~frames")
        self.assertGreater(len(frames), 0)
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        start = rospy.Time.now()
        missing = []
        for frame in frames:
            if not buf.can_transform("base_link", frame, rospy.Time(0), rospy.Duration(timeout)):
                missing.append(frame)
        self.assertEqual(missing, [], "frames not on /tf within %.1f s: %s" % (timeout, missing))
        # link_1 moves with joint_1: at the zero pose that joint_state_publisher sends, the forearm
        # points along +x, so the flange is in front of the robot, above the shoulder
        t = buf.lookup_transform("base_link", "flange", rospy.Time(0)).transform.translation
        self.assertGreater(t.x, 0.5)
        self.assertAlmostEqual(t.y, 0.0, places=6)
        self.assertGreater(t.z, 0.8)
        rospy.loginfo("all %d frames on /tf after %.2f s", len(frames), (rospy.Time.now() - start).to_sec())


if __name__ == "__main__":
    rospy.init_node("tf_frames_check")
    rostest.rosrun("panasonic_vr006l_support", "tf_frames_check", TfFrames, sys.argv)
