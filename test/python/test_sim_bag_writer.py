"""The simulator's pre-serialized bag messages are byte for byte what genpy serializes for the same message."""

from __future__ import annotations

import io

import numpy as np
import rosbag
import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, PointCloud2

from grid_puzzle_localization.ros.bags.writer import BagNames, ScenarioBag
from grid_puzzle_localization.ros.msgs.cloud import array_to_cloud
from grid_puzzle_localization.sim.lidar import POINT_DTYPE

NAMES = BagNames(points_topic="scan", imu_topic="imu/data", map_frame="world", base_frame="body", lidar_frame="velo")


def _genpy_bytes(msg) -> bytes:
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.getvalue()


def _raw_messages(path) -> dict[str, list[tuple[bytes, int]]]:
    out = {}
    with rosbag.Bag(str(path)) as bag:
        for topic, raw, t in bag.read_messages(raw=True):
            out.setdefault(topic, []).append((raw[1], t.to_nsec()))
    return out


def test_imu_ground_truth_and_points_match_genpy(tmp_path):
    rng = np.random.default_rng(3)
    stamps = 1_700_000_000_000_000_000 + np.arange(5) * 5_000_000 + 7  # nanoseconds, not a whole ms
    gyro, accel, pos, vel, ang = (rng.normal(size=(5, 3)) for _ in range(5))
    quat = rng.normal(size=(5, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    points = np.zeros(1000, dtype=POINT_DTYPE)
    for name in ("x", "y", "z", "intensity", "time"):
        points[name] = rng.normal(size=1000)
    points["ring"] = rng.integers(0, 32, 1000)
    with ScenarioBag(str(tmp_path / "a.bag"), NAMES) as bag:
        bag.write_imu(stamps, gyro, accel, 0.01, 0.02)
        bag.write_ground_truth(stamps[::2], pos[::2], quat[::2], vel[::2], ang[::2])
        bag.write_points(int(stamps[0]), int(stamps[-1]), points)
    written = _raw_messages(tmp_path / "a.bag")

    for j, (data, t) in enumerate(written["imu/data"]):
        msg = Imu()
        msg.header.stamp = rospy.Time(nsecs=int(stamps[j]))
        msg.header.frame_id = "body"
        msg.orientation_covariance[0] = -1.0
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = gyro[j]
        msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = accel[j]
        msg.angular_velocity_covariance = [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01]
        msg.linear_acceleration_covariance = [0.02, 0, 0, 0, 0.02, 0, 0, 0, 0.02]
        assert data == _genpy_bytes(msg) and t == stamps[j]
    assert len(written["imu/data"]) == 5

    for j, (data, t) in enumerate(written["ground_truth"]):
        k = 2 * j
        msg = Odometry()
        msg.header.stamp = rospy.Time(nsecs=int(stamps[k]))
        msg.header.frame_id, msg.child_frame_id = "world", "body"
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        p.x, p.y, p.z = pos[k]
        q.x, q.y, q.z, q.w = quat[k]
        v, w = msg.twist.twist.linear, msg.twist.twist.angular
        v.x, v.y, v.z = vel[k]
        w.x, w.y, w.z = ang[k]
        assert data == _genpy_bytes(msg) and t == stamps[k]
    assert len(written["ground_truth"]) == 3

    [(data, t)] = written["scan"]
    cloud: PointCloud2 = array_to_cloud(points, frame_id="velo", stamp=rospy.Time(nsecs=int(stamps[0])))
    assert data == _genpy_bytes(cloud) and t == stamps[-1]
