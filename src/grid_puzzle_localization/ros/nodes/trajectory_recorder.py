"""Node that records an Odometry topic as a TUM trajectory, written when the node shuts down.

Subscribes: ``odom`` (nav_msgs/Odometry) and, when ``~scan_times`` (a CSV path) is set, ``status`` (the
localizer's NdtStatus, for its per-scan times, whether each match was accepted and what it did). Parameters: ``~output``
(path of the TUM file). Optionally publishes, once and latched (geometry_msgs/PoseWithCovarianceStamped in
``~frame_id``, default ``map``), ``~initial_pose`` (7 numbers x y z qx qy qz qw) on ``initialpose``, which is how
the experiment seeds the localizer and the map provider, and ``~hint`` (x, y [m] and its standard deviation
sigma [m]) on ``initialpose_hint``, a coarse position for the localizer's global search and the provider's first
window. Latched, each reaches a subscriber that connects later. Poses whose stamp does not increase (a bag
restarted) are dropped and counted."""

from __future__ import annotations

import numpy as np
import rospy
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.scan_times import write_scan_times
from grid_puzzle_localization.evaluation.trajectory import make_trajectory, write_tum
from grid_puzzle_localization.msg import NdtStatus


class TrajectoryRecorder:
    def __init__(self, output: str, scan_times: str | None):
        self.output = output
        self.scan_times_output = scan_times
        self.rows: list[tuple[float, ...]] = []
        self.scan_times: list[tuple[float, float, float, bool, int, int, bool, float, float]] = []
        self.dropped = 0
        self.sub = rospy.Subscriber("odom", Odometry, self.on_odom, queue_size=100)
        if scan_times:
            self.status_sub = rospy.Subscriber("status", NdtStatus, self.on_status, queue_size=100)

    def on_status(self, msg: NdtStatus) -> None:
        if msg.state != "tracking":  # a scan that waited for the map or a pose: no match was tried
            return
        self.scan_times.append(
            (
                msg.header.stamp.to_sec(),
                msg.scan_time_ms,
                msg.align_time_ms,
                msg.match_accepted,
                msg.iterations,
                msg.hypotheses,
                msg.global_search,
                msg.nvtl,
                msg.map_worker_cpu_s,
            )
        )

    def on_odom(self, msg: Odometry) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        t = msg.header.stamp.to_sec()
        if self.rows and t <= self.rows[-1][0]:
            self.dropped += 1
            return
        self.rows.append((t, p.x, p.y, p.z, q.x, q.y, q.z, q.w))

    def write(self) -> None:
        data = np.array(self.rows, dtype=np.float64).reshape(-1, 8)
        write_tum(self.output, make_trajectory(data[:, 0], data[:, 1:4], data[:, 4:8], source="odom"))
        rospy.loginfo(f"trajectory_recorder: wrote {len(data)} poses to {self.output} (dropped {self.dropped})")
        if self.scan_times_output:
            write_scan_times(self.scan_times_output, self.scan_times)


def initial_pose_message(values: list[float], frame_id: str) -> PoseWithCovarianceStamped:
    if len(values) != 7:
        raise UserError(f"~initial_pose needs 7 numbers x y z qx qy qz qw (got {values})")
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    pose = msg.pose.pose
    pose.position.x, pose.position.y, pose.position.z = values[:3]
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = values[3:]
    # 10 cm, 1 degree: the ground truth's first pose.
    msg.pose.covariance = list(np.diag([0.01, 0.01, 0.01, 3e-4, 3e-4, 3e-4]).ravel())
    return msg


def hint_message(values: list[float], frame_id: str) -> PoseWithCovarianceStamped:
    """A coarse position (x, y [m], sigma [m]): its covariance holds sigma^2 in x and y; z, roll, pitch and yaw are
    unknown (variance 1e6)."""
    if len(values) != 3 or not values[2] >= 0:
        raise UserError(f"~hint needs 3 numbers x y sigma, sigma >= 0 m (got {values})")
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.pose.pose.position.x, msg.pose.pose.position.y = values[:2]
    msg.pose.pose.orientation.w = 1.0
    sigma2 = values[2] ** 2
    msg.pose.covariance = list(np.diag([sigma2, sigma2, 1e6, 1e6, 1e6, 1e6]).ravel())
    return msg


def main() -> None:
    rospy.init_node("trajectory_recorder")
    output = rospy.get_param("~output")
    recorder = TrajectoryRecorder(output, rospy.get_param("~scan_times", None))
    initial = rospy.get_param("~initial_pose", None)
    if initial is not None:
        pub = rospy.Publisher("initialpose", PoseWithCovarianceStamped, queue_size=1, latch=True)
        pub.publish(initial_pose_message([float(v) for v in initial], rospy.get_param("~frame_id", "map")))
    hint = rospy.get_param("~hint", None)
    if hint is not None:
        hint_pub = rospy.Publisher("initialpose_hint", PoseWithCovarianceStamped, queue_size=1, latch=True)
        hint_pub.publish(hint_message([float(v) for v in hint], rospy.get_param("~frame_id", "map")))
    rospy.on_shutdown(recorder.write)
    rospy.spin()
