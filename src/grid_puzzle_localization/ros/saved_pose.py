"""A node's last pose kept on the parameter server, as amcl keeps its own (save_pose_rate) and as the C++ nodelets
do (src/nodelets/saved_pose.hpp): ``~last_pose`` {pose: [x y z roll pitch yaw] (m, rad), stamp (s)}, written in one
call by a thread of its own at a wall-clock rate, only when a new pose came, and read back by a respawned node."""

from __future__ import annotations

import math
import threading

import rospy


def read_saved_pose() -> list[float] | None:
    """``~last_pose/pose`` when it is 6 finite numbers; a malformed value (state, not a setting) is logged, ignored."""
    saved = rospy.get_param("~last_pose/pose", None)
    if saved is None:
        return None
    try:
        values = [float(v) for v in saved]
    except (TypeError, ValueError):
        values = []
    if len(values) == 6 and all(math.isfinite(v) for v in values):
        return values
    rospy.logwarn("parameter ~last_pose/pose = %r is not 6 finite numbers [x y z roll pitch yaw]; ignored", saved)
    return None


class SavedPoseWriter:
    """Writes the newest pose given to ``set`` to ``~last_pose`` every ``1 / rate`` s of wall time (rate 0: never)."""

    def __init__(self, rate: float) -> None:
        self._lock = threading.Lock()
        self._value: dict | None = None
        self._new = threading.Event()
        if rate > 0.0:
            threading.Thread(target=self._run, args=(1.0 / rate,), name="saved_pose", daemon=True).start()

    def set(self, xyz_rpy: list[float], stamp: float) -> None:
        with self._lock:
            self._value = {"pose": [float(v) for v in xyz_rpy], "stamp": float(stamp)}
        self._new.set()

    def _run(self, period: float) -> None:
        while not rospy.is_shutdown():
            self._new.wait()
            self._new.clear()
            with self._lock:
                value = self._value
            rospy.set_param("~last_pose", value)
            rospy.rostime.wallsleep(period)
