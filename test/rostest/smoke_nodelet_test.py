#!/usr/bin/env python3
"""Publishes a cloud with NaN, origin and far points into the preprocessor nodelet and checks
that exactly the valid points come out."""

import unittest

import numpy as np
import rospy
import rostest
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

FIELDS = [PointField(name, 4 * i, PointField.FLOAT32, 1) for i, name in enumerate("xyz")]


class SmokeNodeletTest(unittest.TestCase):
    def test_cloud_goes_through_nodelet(self):
        rospy.init_node("smoke_nodelet_test")
        received = []
        rospy.Subscriber("points_filtered", PointCloud2, received.append)
        pub = rospy.Publisher("points", PointCloud2, queue_size=1, latch=True)
        points = [(float("nan"), 1.0, 1.0), (0.0, 0.0, 0.0), (3.0, 4.0, 0.0), (80.0, 0.0, 0.0), (0.0, -2.0, 1.0)]
        cloud = point_cloud2.create_cloud(Header(frame_id="lidar"), FIELDS, points)
        deadline = rospy.Time.now() + rospy.Duration(30.0)
        while not received and rospy.Time.now() < deadline and not rospy.is_shutdown():
            cloud.header.stamp = rospy.Time.now()
            pub.publish(cloud)
            rospy.sleep(0.2)
        self.assertTrue(received, "no cloud came out of the nodelet on points_filtered")
        out = np.array(list(point_cloud2.read_points(received[0], field_names="xyz")))
        np.testing.assert_array_equal(out, np.array([[3.0, 4.0, 0.0], [0.0, -2.0, 1.0]]))
        self.assertEqual(received[0].header.frame_id, "lidar")


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "smoke_nodelet", SmokeNodeletTest)
