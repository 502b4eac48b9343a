"""Writes a rosbag of a synthetic drive (``grid_puzzle_localization.synthetic_scene``): HDL-32E-like
scans on ``points`` (frame ``lidar``), the base_link -> lidar mounting on ``/tf_static`` (latched) and
the true map_T_base on ``ground_truth`` (geometry_msgs/PoseStamped, frame ``map``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import PoseStamped, TransformStamped
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header
from tf2_msgs.msg import TFMessage

from grid_puzzle_localization import synthetic_scene as ss
from grid_puzzle_localization.pcd.reader import xyz_records
from grid_puzzle_localization.ros.cloud_msg import array_to_cloud


def xyz_cloud(points: np.ndarray, header: Header) -> PointCloud2:
    """A dense x y z float32 PointCloud2 from an ``(N, 3)`` array."""
    return array_to_cloud(xyz_records(points), header=header)


def _pose_fields(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return m[:3, 3], Rotation.from_matrix(m[:3, :3]).as_quat()


def write_drive_bag(path: Path, scene: ss.Scene, drive: ss.Drive, start: float = 1000.0, seed: int = 5) -> None:
    """Writes the bag atomically (temporary file in the same directory, then rename). ``start`` [s] is
    the bag time of the first scan."""
    rng = np.random.default_rng(seed)
    tmp = path.with_name(path.name + ".tmp")
    t0 = rospy.Time.from_sec(start)
    with rosbag.Bag(str(tmp), "w") as bag:
        mount = TransformStamped()
        mount.header = Header(stamp=t0, frame_id="base_link")
        mount.child_frame_id = "lidar"
        xyz, q = _pose_fields(ss.lidar_mount())
        mount.transform.translation.x, mount.transform.translation.y, mount.transform.translation.z = xyz
        r = mount.transform.rotation
        r.x, r.y, r.z, r.w = q
        static = TFMessage([mount])
        latched = {"type": static._type, "md5sum": static._md5sum, "message_definition": static._full_text}
        bag.write("/tf_static", static, t0, connection_header={**latched, "latching": "1", "callerid": "/synthetic"})
        for t in drive.stamps:
            stamp = rospy.Time.from_sec(start + float(t))
            pose = drive.pose(float(t))
            bag.write("/points", xyz_cloud(ss.scan(scene, pose, rng), Header(stamp=stamp, frame_id="lidar")), stamp)
            truth = PoseStamped(header=Header(stamp=stamp, frame_id="map"))
            xyz, q = _pose_fields(pose)
            p, o = truth.pose.position, truth.pose.orientation
            p.x, p.y, p.z = xyz
            o.x, o.y, o.z, o.w = q
            bag.write("/ground_truth", truth, stamp)
    tmp.replace(path)
