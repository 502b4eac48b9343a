"""Writes a simulated scenario into a rosbag with the rosbag Python API.

Topics (names are parameters; these are the defaults): ``points`` (sensor_msgs/PointCloud2 in the
lidar frame, fields x y z intensity ring time, header.stamp = sweep start, recorded at the sweep end),
``imu`` (sensor_msgs/Imu in base_link), ``ground_truth`` (nav_msgs/Odometry map -> base_link, twist in
base_link) and ``/tf_static`` (base_link -> lidar, latched). Every record time is set explicitly, so the
same inputs give the same bytes. Messages must be written in non-decreasing record time.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, PointCloud2
from std_msgs.msg import Header
from tf2_msgs.msg import TFMessage

from grid_puzzle_localization.ros.msgs.streamed import StreamedCloud


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


def _header_fields(frame: str) -> list[tuple]:
    """Serialized std_msgs/Header (seq, stamp, frame_id) as packed numpy fields."""
    return [("seq", "<u4"), ("secs", "<u4"), ("nsecs", "<u4"), *_string_fields(frame, "frame")]


def _string_fields(text: str, name: str) -> list[tuple]:
    n = len(text.encode())
    return [(f"{name}_len", "<u4")] + ([(name, f"S{n}")] if n else [])


# sensor_msgs/Imu and nav_msgs/Odometry after their header(s), as genpy serializes them (packed, little-endian).
_IMU_BODY = [
    ("orientation", "<f8", 4),
    ("orientation_covariance", "<f8", 9),
    ("angular_velocity", "<f8", 3),
    ("angular_velocity_covariance", "<f8", 9),
    ("linear_acceleration", "<f8", 3),
    ("linear_acceleration_covariance", "<f8", 9),
]
_ODOMETRY_BODY = [
    ("position", "<f8", 3),
    ("orientation", "<f8", 4),
    ("pose_covariance", "<f8", 36),
    ("linear", "<f8", 3),
    ("angular", "<f8", 3),
    ("twist_covariance", "<f8", 36),
]


def _records(dtype: np.dtype, stamps_ns: np.ndarray, strings: dict[str, str]) -> np.ndarray:
    """Zeroed serialized messages of ``dtype`` with header stamps and the string fields filled in."""
    rec = np.zeros(len(stamps_ns), dtype=dtype)
    rec["secs"], rec["nsecs"] = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 10**9)
    for name, text in strings.items():
        rec[f"{name}_len"] = len(text.encode())
        if text:
            rec[name] = text.encode()
    return rec


class ScenarioBag:
    """Context manager around a rosbag.Bag opened for writing (uncompressed, fixed chunk threshold).

    Messages are serialized here, many at a time with numpy for the IMU and ground truth, and handed to
    rosbag pre-serialized (``raw``); the bytes equal genpy's serialization of the same message."""

    def __init__(self, path: str, names: BagNames) -> None:
        self._bag = rosbag.Bag(path, "w", chunk_threshold=4 * 1024 * 1024)
        self.names = names
        self._imu_dtype = np.dtype(_header_fields(names.base_frame) + _IMU_BODY)
        self._odometry_dtype = np.dtype(
            _header_fields(names.map_frame) + _string_fields(names.base_frame, "child") + _ODOMETRY_BODY
        )

    def __enter__(self) -> ScenarioBag:
        return self

    def __exit__(self, *exc) -> None:
        self._bag.close()

    def _write_raw(self, topic: str, msg_class, records: np.ndarray, stamps_ns: np.ndarray) -> None:
        data, size = records.tobytes(), records.dtype.itemsize
        for j, ns in enumerate(stamps_ns.tolist()):
            raw = (msg_class._type, data[j * size : (j + 1) * size], msg_class._md5sum, msg_class)
            self._bag.write(topic, raw, rospy.Time(nsecs=ns), raw=True)

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

    def write_points(self, stamp_ns: int, record_ns: int, points: np.ndarray) -> None:
        """A sweep (structured array, lidar frame) stamped at its start, recorded at ``record_ns``,
        serialised straight from the array (streamed_msgs)."""
        header = Header(stamp=rospy.Time(nsecs=stamp_ns), frame_id=self.names.lidar_frame)
        data = np.ascontiguousarray(points)
        buffer = io.BytesIO()
        StreamedCloud(header, data.dtype, lambda: [data], is_dense=True).serialize(buffer)
        raw = (PointCloud2._type, buffer.getvalue(), PointCloud2._md5sum, PointCloud2)
        self._bag.write(self.names.points_topic, raw, rospy.Time(nsecs=record_ns), raw=True)

    def write_imu(
        self, stamps_ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gyro_var: float, accel_var: float
    ) -> None:
        """IMU samples (k,) stamps [ns], (k, 3) angular velocity [rad/s] and acceleration [m/s^2], with
        diagonal covariances; no orientation (orientation_covariance[0] = -1)."""
        rec = _records(self._imu_dtype, stamps_ns, {"frame": self.names.base_frame})
        rec["orientation_covariance"][:, 0] = -1.0
        rec["angular_velocity"], rec["linear_acceleration"] = gyro, accel
        rec["angular_velocity_covariance"][:, ::4] = gyro_var
        rec["linear_acceleration_covariance"][:, ::4] = accel_var
        self._write_raw(self.names.imu_topic, Imu, rec, stamps_ns)

    def write_ground_truth(
        self,
        stamps_ns: np.ndarray,
        position: np.ndarray,
        quat_xyzw: np.ndarray,
        velocity_body: np.ndarray,
        gyro_body: np.ndarray,
    ) -> None:
        """Poses of base_link in map (k, 3) [m] and (k, 4), twist in base_link (k, 3) [m/s] and [rad/s]."""
        rec = _records(self._odometry_dtype, stamps_ns, {"frame": self.names.map_frame, "child": self.names.base_frame})
        rec["position"], rec["orientation"] = position, quat_xyzw
        rec["linear"], rec["angular"] = velocity_body, gyro_body
        self._write_raw(self.names.ground_truth_topic, Odometry, rec, stamps_ns)
