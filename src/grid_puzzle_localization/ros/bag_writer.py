"""Writes a simulated scenario into a rosbag with the rosbag Python API.

Topics (names are parameters; these are the defaults): ``points`` (sensor_msgs/PointCloud2 in the
lidar frame, fields x y z intensity ring time, header.stamp = sweep start, recorded at the sweep end),
``imu`` (sensor_msgs/Imu in base_link), ``ground_truth`` (nav_msgs/Odometry map -> base_link, twist in
base_link) and ``/tf_static`` (base_link -> lidar, latched). Every record time is set explicitly, so the
same inputs give the same bytes. Messages must be written in non-decreasing record time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, PointCloud2, PointField
from tf2_msgs.msg import TFMessage

_NUMPY_TO_POINTFIELD = {
    np.dtype("<f4"): PointField.FLOAT32,
    np.dtype("<f8"): PointField.FLOAT64,
    np.dtype("<u2"): PointField.UINT16,
    np.dtype("<u1"): PointField.UINT8,
    np.dtype("<i4"): PointField.INT32,
    np.dtype("<u4"): PointField.UINT32,
}


@dataclass(frozen=True)
class BagNames:
    """Topic and frame names written into the bag."""

    points_topic: str = "points"
    imu_topic: str = "imu"
    ground_truth_topic: str = "ground_truth"
    map_frame: str = "map"
    base_frame: str = "base_link"
    lidar_frame: str = "lidar"


def _stamp(t: float) -> rospy.Time:
    """Exact nanosecond stamp of ``t`` seconds (rounded once, so equal inputs give equal bytes)."""
    return rospy.Time(nsecs=round(t * 1e9))


def _point_fields(dtype: np.dtype) -> list[PointField]:
    return [
        PointField(name=name, offset=off, datatype=_NUMPY_TO_POINTFIELD[dt], count=1)
        for name, (dt, off) in dtype.fields.items()
    ]


class ScenarioBag:
    """Context manager around a rosbag.Bag opened for writing (uncompressed, fixed chunk threshold)."""

    def __init__(self, path: str, names: BagNames) -> None:
        self._bag = rosbag.Bag(path, "w", chunk_threshold=4 * 1024 * 1024)
        self.names = names

    def __enter__(self) -> ScenarioBag:
        return self

    def __exit__(self, *exc) -> None:
        self._bag.close()

    def write_tf_static(self, t: float, translation: np.ndarray, quat_xyzw: np.ndarray) -> None:
        """The base_link -> lidar mount, latched like a static_transform_publisher."""
        tf = TransformStamped()
        tf.header.stamp = _stamp(t)
        tf.header.frame_id = self.names.base_frame
        tf.child_frame_id = self.names.lidar_frame
        tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = map(float, translation)
        r = tf.transform.rotation
        r.x, r.y, r.z, r.w = map(float, quat_xyzw)
        msg = TFMessage(transforms=[tf])
        header = {
            "topic": "/tf_static",
            "type": msg._type,
            "md5sum": msg._md5sum,
            "message_definition": msg._full_text,
            "latching": "1",
            "callerid": "/gpm_simulate",
        }
        self._bag.write("/tf_static", msg, _stamp(t), connection_header=header)

    def write_points(self, stamp: float, record_time: float, points: np.ndarray) -> None:
        """A sweep (structured array, lidar frame) stamped at its start, recorded at ``record_time``."""
        msg = PointCloud2()
        msg.header.stamp = _stamp(stamp)
        msg.header.frame_id = self.names.lidar_frame
        msg.height, msg.width = 1, len(points)
        msg.fields = _point_fields(points.dtype)
        msg.is_bigendian = False
        msg.point_step = points.dtype.itemsize
        msg.row_step = msg.point_step * len(points)
        msg.is_dense = True
        msg.data = np.ascontiguousarray(points).tobytes()
        self._bag.write(self.names.points_topic, msg, _stamp(record_time))

    def write_imu(self, t: float, gyro: np.ndarray, accel: np.ndarray, gyro_var: float, accel_var: float) -> None:
        msg = Imu()
        msg.header.stamp = _stamp(t)
        msg.header.frame_id = self.names.base_frame
        msg.orientation_covariance[0] = -1.0  # no orientation estimate
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = map(float, gyro)
        msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = map(float, accel)
        msg.angular_velocity_covariance = [gyro_var, 0.0, 0.0, 0.0, gyro_var, 0.0, 0.0, 0.0, gyro_var]
        msg.linear_acceleration_covariance = [accel_var, 0.0, 0.0, 0.0, accel_var, 0.0, 0.0, 0.0, accel_var]
        self._bag.write(self.names.imu_topic, msg, msg.header.stamp)

    def write_ground_truth(
        self, t: float, position: np.ndarray, quat_xyzw: np.ndarray, velocity_body: np.ndarray, gyro_body: np.ndarray
    ) -> None:
        msg = Odometry()
        msg.header.stamp = _stamp(t)
        msg.header.frame_id = self.names.map_frame
        msg.child_frame_id = self.names.base_frame
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        p.x, p.y, p.z = map(float, position)
        q.x, q.y, q.z, q.w = map(float, quat_xyzw)
        v, w = msg.twist.twist.linear, msg.twist.twist.angular
        v.x, v.y, v.z = map(float, velocity_body)
        w.x, w.y, w.z = map(float, gyro_body)
        self._bag.write(self.names.ground_truth_topic, msg, msg.header.stamp)
