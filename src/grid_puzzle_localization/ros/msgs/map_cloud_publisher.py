"""The latched merged ``map_cloud`` of grid_puzzle_map_provider (off by default), published by a thread
of its own.

The cloud is streamed from the window's tile files (streamed.StreamedCloud): the latched message holds
only the way to read them, and rospy serialises it (reading the files into one window-sized copy, freed
once sent) only while the topic has subscribers, so with nobody subscribed it costs nothing. At the
paper's window (n 25, k 20: up to 71 x 71 tiles, about 90 MB at the paper's point density) that copy is
large, so this thread publishes at most once per ``period`` [s], always the latest window, and the
worker never waits for it: the tile deltas the localizer needs are not held up by the display cloud. The
publisher is synchronous (no queue_size): publish() returns once the cloud is sent, so one serialised
copy exists at a time.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rospy
from sensor_msgs.msg import PointCloud2

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.ros.msgs.provider import stamped
from grid_puzzle_localization.ros.msgs.streamed import StreamedCloud
from grid_puzzle_localization.tiles.reader import read_tile
from grid_puzzle_localization.util.malloc_tuning import trim_heap

WARN_PERIOD = 5.0  # [s] throttle of the unreadable-tile warning


def read_tiles(paths: list[Path]) -> list[np.ndarray]:
    """x, y, z of the readable tiles among ``paths``; an unreadable one is logged and left out."""
    parts = []
    for path in paths:
        try:
            parts.append(read_tile(path, xyz_only=True))
        except (PcdError, OSError) as err:
            rospy.logwarn_throttle(WARN_PERIOD, "map_cloud: tile %s left out: %s", path, err)
    return parts


class MapCloudPublisher:
    def __init__(self, window_paths: Callable[[], list[Path]], frame: str, period: float) -> None:
        """``window_paths()``: the tile files of the current window (called when a subscriber reads)."""
        self._window_paths = window_paths
        self._frame = frame
        self._period = period
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SyntaxWarning)  # rospy's hint to set queue_size: synchronous on purpose
            self._pub = rospy.Publisher("map_cloud", PointCloud2, latch=True, queue_size=None)
        self._cond = threading.Condition()
        self._pending: rospy.Time | None = None  # stamp of the newest window not yet published
        threading.Thread(target=self._run, name="map_cloud_publisher", daemon=True).start()

    def changed(self, stamp: rospy.Time) -> None:
        """The loaded window changed (at ``stamp``): publish it when the period allows. Never blocks."""
        with self._cond:
            self._pending = stamp
            self._cond.notify()

    def _run(self) -> None:
        not_before = 0.0  # [monotonic s]
        while not rospy.is_shutdown():
            with self._cond:
                if self._pending is None or time.monotonic() < not_before:
                    wait = 0.5 if self._pending is None else min(0.5, not_before - time.monotonic())
                    self._cond.wait(max(wait, 0.0))
                    continue
                stamp, self._pending = self._pending, None
            header = stamped(self._frame, stamp)
            cloud = StreamedCloud(header, XYZ_DTYPE, lambda: read_tiles(self._window_paths()), is_dense=True)
            self._pub.publish(cloud)
            trim_heap()  # the tiles read for the subscribers are freed: give the pages back
            not_before = time.monotonic() + self._period
