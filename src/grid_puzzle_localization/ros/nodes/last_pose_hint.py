"""last_pose_hint: keeps the localizer's last published position outside the localizer's process.

Subscribes to ``odom`` (nav_msgs/Odometry, map frame) and republishes the newest pose, at most every ``~period``
seconds (default 1.0), as the latched ``initialpose_hint`` (geometry_msgs/PoseWithCovarianceStamped). A localizer
that is killed and respawned starts without a pose: it publishes nothing and, with
``global_localization/auto_start_timeout`` > 0, runs its global search around this hint (the square of
``global_localization/size``), so it resumes near where it stopped instead of searching the whole map."""

from __future__ import annotations

import rospy
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry


class LastPoseHint:
    def __init__(self, period: float) -> None:
        self.period = rospy.Duration.from_sec(period)
        self.last_sent: rospy.Time | None = None
        self.pub = rospy.Publisher("initialpose_hint", PoseWithCovarianceStamped, queue_size=1, latch=True)
        self.sub = rospy.Subscriber("odom", Odometry, self.on_odom, queue_size=1)

    def on_odom(self, msg: Odometry) -> None:
        stamp = msg.header.stamp
        # A stamp going backwards (a bag restarted) sends at once rather than waiting out the period.
        if self.last_sent is not None and self.last_sent <= stamp < self.last_sent + self.period:
            return
        self.last_sent = stamp
        self.pub.publish(PoseWithCovarianceStamped(header=msg.header, pose=msg.pose))


def main() -> None:
    rospy.init_node("last_pose_hint")
    period = float(rospy.get_param("~period", 1.0))
    if not period >= 0.0:
        rospy.logfatal(f"~period must be >= 0 s (got {period}); fix it in the launch file")
        raise SystemExit(1)
    LastPoseHint(period)
    rospy.spin()
