"""Pose conversion of the provider node against closed forms."""

import math

import pytest
import rospy
from geometry_msgs.msg import Pose, Quaternion, Twist

from grid_puzzle_localization.ros.msgs.provider import pose_sample, yaw_of


@pytest.mark.parametrize("yaw", [0.0, 0.3, math.pi / 2, 2.5, -2.5, -math.pi / 2])
def test_yaw_of_a_yaw_only_quaternion(yaw):
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    assert yaw_of(q) == pytest.approx(yaw, abs=1e-12)


def test_unset_orientation_has_no_yaw():
    assert yaw_of(Quaternion(0.0, 0.0, 0.0, 0.0)) is None


def test_body_twist_becomes_a_map_velocity():
    pose = Pose()
    pose.position.x, pose.position.y = 3.0, -4.0
    yaw = math.pi / 2  # facing +y: forward speed 2 m/s is +y in the map, leftward 1 m/s is -x
    pose.orientation = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    twist = Twist()
    twist.linear.x, twist.linear.y = 2.0, 1.0
    sample = pose_sample(pose, rospy.Time(12, 500_000_000), twist)
    assert (sample.x, sample.y, sample.t) == (3.0, -4.0, 12.5)
    assert sample.velocity == pytest.approx((-1.0, 2.0))
    assert sample.yaw == pytest.approx(yaw)
