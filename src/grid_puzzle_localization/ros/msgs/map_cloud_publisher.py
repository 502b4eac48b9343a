"""The latched merged ``map_cloud`` of grid_puzzle_map_provider, published by a thread of its own.

The cloud is streamed from the store's tile arrays (streamed_msgs.StreamedCloud): the latched message
holds no copy of the window, and rospy serialises it, one window-sized copy freed once sent, only while
the topic has subscribers. At the paper's window (n 25, k 20: up to 71 x 71 tiles, about 90 MB at the
paper's point density) that copy is still large, so this thread publishes at most once per ``period``
[s], always the latest window, and the worker never waits for it: the tile deltas the localizer needs
are not held up by the display cloud. The publisher is synchronous (no queue_size): publish() returns
once the cloud is sent, so one serialised copy exists at a time, where a queued publisher keeps one
queued and one in flight besides the one being built when a subscriber (rviz) reads slowly.
"""

from __future__ import annotations

import threading
import time
import warnings

import rospy
from sensor_msgs.msg import PointCloud2

from grid_puzzle_localization.provider.tile_store import TileStore
from grid_puzzle_localization.ros.msgs.provider import stamped
from grid_puzzle_localization.ros.msgs.streamed import StreamedCloud


class MapCloudPublisher:
    def __init__(self, store: TileStore, frame: str, period: float) -> None:
        self._store = store
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
            self._pub.publish(StreamedCloud(header, self._store.dtype, self._store.point_arrays, is_dense=True))
            not_before = time.monotonic() + self._period
