"""Scans from a ROS bag (sensor_msgs/PointCloud2) with poses interpolated from a TUM trajectory.

Also reads the sensor->robot extrinsic from the bag's ``/tf_static`` (a direct edge only).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import rosbag

from grid_puzzle_localization.blocks.keyframes import Scan
from grid_puzzle_localization.blocks.poses import Trajectory, pose_matrix
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import xyz_array
from grid_puzzle_localization.ros.msgs.cloud import cloud_to_array


def _xyz(msg) -> np.ndarray:
    """(N, 3) float64 sensor-frame points of a PointCloud2 (non-finite ones are dropped by the builder)."""
    try:
        return xyz_array(cloud_to_array(msg))
    except (ValueError, KeyError) as err:
        raise UserError(f"a cloud on the bag's scan topic cannot be read as x, y, z points: {err}") from err


def _open(path: str | os.PathLike) -> rosbag.Bag:
    try:
        return rosbag.Bag(str(path))
    except (OSError, rosbag.ROSBagException) as err:
        raise UserError(f"cannot open bag {path}: {err}; give a readable ROS 1 bag") from err


@dataclass
class BagScans:
    """Iterates the scans on ``topic`` whose stamp lies inside the trajectory's time span, in bag order;
    ``skipped`` counts the others (no pose is extrapolated)."""

    path: str | os.PathLike
    topic: str
    trajectory: Trajectory
    skipped: int = 0

    def __iter__(self) -> Iterator[Scan]:
        with _open(self.path) as bag:
            topics = bag.get_type_and_topic_info().topics
            if self.topic not in topics:
                raise UserError(
                    f"bag {self.path} has no topic '{self.topic}' (it has: {', '.join(sorted(topics))}); pass --topic"
                )
            for _, msg, _ in bag.read_messages(topics=[self.topic]):
                stamp = msg.header.stamp.to_sec()
                poses, inside = self.trajectory.interpolate(np.array([stamp]))
                if not inside[0]:
                    self.skipped += 1
                    continue
                yield Scan(stamp, poses[0], lambda msg=msg: _xyz(msg))


def bag_extrinsic(path: str | os.PathLike, topic: str, robot_frame: str) -> np.ndarray:
    """``T_robot_sensor`` from ``/tf_static``: the edge ``robot_frame`` -> frame of the first cloud on ``topic``."""
    with _open(path) as bag:
        sensor_frame = None
        for _, msg, _ in bag.read_messages(topics=[topic]):
            sensor_frame = msg.header.frame_id.lstrip("/")
            break
        if sensor_frame is None:
            raise UserError(f"bag {path} has no message on '{topic}' to take the sensor frame from; pass --topic")
        robot_frame = robot_frame.lstrip("/")
        if sensor_frame == robot_frame:
            return np.eye(4)
        for _, msg, _ in bag.read_messages(topics=["/tf_static", "tf_static"]):
            for tf in msg.transforms:
                if (tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/")) == (robot_frame, sensor_frame):
                    t, q = tf.transform.translation, tf.transform.rotation
                    return pose_matrix(np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w]))
    raise UserError(
        f"bag {path} has no /tf_static transform {robot_frame} -> {sensor_frame}; "
        "pass --extrinsic 'x y z qx qy qz qw' or --robot-frame"
    )
