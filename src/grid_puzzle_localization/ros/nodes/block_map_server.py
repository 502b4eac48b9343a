"""block_map_server: publishes the nearest blocks of a block map as a latched `map_cloud`.

Subscribes: `odom` (nav_msgs/Odometry) or `pose` (geometry_msgs/PoseWithCovarianceStamped), per
~pose_type, and `initialpose` (PoseWithCovarianceStamped), all in ~map_frame; ~initial_pose selects
the first blocks at startup. Publishes: `map_cloud` (sensor_msgs/PointCloud2, latched, ~map_frame),
`~status` (BlockMapStatus). Service: `~query_blocks` (QueryBlocks). Selection, loading and merging are
the pure modules in grid_puzzle_localization.blocks; loads run on a worker thread that only ever
handles the latest pose.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import threading
import time

import numpy as np
import rospy
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2

from grid_puzzle_localization.blocks.block_cache import BlockCache
from grid_puzzle_localization.blocks.select import BlockSelector
from grid_puzzle_localization.blocks.server_config import BlockMapServerConfig
from grid_puzzle_localization.blocks.store import read_block_index
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.msg import BlockMapStatus
from grid_puzzle_localization.ros.msgs.cloud import array_to_cloud
from grid_puzzle_localization.srv import QueryBlocks, QueryBlocksResponse


def read_config() -> BlockMapServerConfig:
    """The node's private parameters, each defaulting to the dataclass field default."""
    values = {}
    for f in dataclasses.fields(BlockMapServerConfig):
        value = rospy.get_param(f"~{f.name}", f.default)
        values[f.name] = tuple(float(v) for v in value) if isinstance(f.default, tuple) else type(f.default)(value)
    return BlockMapServerConfig(**values).checked()


class BlockMapServer:
    def __init__(self, config: BlockMapServerConfig) -> None:
        self.config = config
        index = read_block_index(config.block_dir)
        self.ids = [entry.id for entry in index.blocks]
        self.selector = BlockSelector(index.centroids(), config.num_blocks, config.planar)
        self.cache = BlockCache(index, config.cache_blocks)
        self.selection: tuple[int, ...] | None = None
        self.switch_count = 0
        self.load_ms = math.nan
        self.points = 0
        self._latest: tuple[np.ndarray, rospy.Time] | None = None
        self._wake = threading.Condition()
        self._cloud_pub = rospy.Publisher("map_cloud", PointCloud2, queue_size=1, latch=True)
        self._status_pub = rospy.Publisher("~status", BlockMapStatus, queue_size=10)
        self._service = rospy.Service("~query_blocks", QueryBlocks, self._on_query)
        self._worker = threading.Thread(target=self._run, name="block_loader", daemon=True)
        self._worker.start()
        if config.pose_type == "odometry":
            self._sub = rospy.Subscriber("odom", Odometry, self._on_pose, queue_size=1)
        else:
            self._sub = rospy.Subscriber("pose", PoseWithCovarianceStamped, self._on_pose, queue_size=1)
        self._initial_sub = rospy.Subscriber("initialpose", PoseWithCovarianceStamped, self._on_pose, queue_size=1)
        if config.initial_pose:
            self._submit(np.array(config.initial_pose[:3]), rospy.Time.now())
        rospy.loginfo(
            f"block_map_server: {len(self.ids)} blocks ({index.kind}) from {config.block_dir}, "
            f"selecting {self.selector.k} nearest"
        )

    def _on_pose(self, msg: Odometry | PoseWithCovarianceStamped) -> None:
        frame = msg.header.frame_id.lstrip("/")
        if frame != self.config.map_frame:
            rospy.logwarn_throttle(
                10.0, f"block_map_server: ignoring poses in frame '{frame}'; ~map_frame is '{self.config.map_frame}'"
            )
            return
        p = msg.pose.pose.position
        position = np.array([p.x, p.y, p.z])
        if not np.all(np.isfinite(position)):
            rospy.logwarn_throttle(10.0, f"block_map_server: ignoring non-finite pose {position.tolist()}")
            return
        self._submit(position, msg.header.stamp)

    def _submit(self, position: np.ndarray, stamp: rospy.Time) -> None:
        with self._wake:
            self._latest = (position, stamp)
            self._wake.notify()

    def _on_query(self, request) -> QueryBlocksResponse:
        p = request.position
        try:
            indices, distances = self.selector.nearest(np.array([p.x, p.y, p.z]))
        except ValueError as err:
            raise rospy.ServiceException(f"query_blocks: {err}") from err
        return QueryBlocksResponse(block_ids=[self.ids[i] for i in indices], distances=distances.tolist())

    def _run(self) -> None:
        while not rospy.is_shutdown():
            with self._wake:
                self._wake.wait_for(lambda: self._latest is not None, timeout=0.5)
                latest, self._latest = self._latest, None
            if latest is not None:
                self._handle(*latest)

    def _handle(self, position: np.ndarray, stamp: rospy.Time) -> None:
        selection = self.selector.select(position)
        if selection != self.selection:
            start = time.perf_counter()
            try:
                cloud = self.cache.merged(selection)
            except UserError as err:
                rospy.logerr_throttle(10.0, f"block_map_server: cannot load blocks {selection}: {err}")
                return
            self.load_ms = (time.perf_counter() - start) * 1e3
            self._cloud_pub.publish(array_to_cloud(cloud, frame_id=self.config.map_frame, stamp=stamp))
            self.selection, self.points = selection, len(cloud)
            self.switch_count += 1
        status = BlockMapStatus(
            selected_ids=[self.ids[i] for i in self.selection],
            switch_count=self.switch_count,
            load_ms=self.load_ms,
            points=self.points,
            blocks_in_memory=len(self.cache),
            block_loads=self.cache.loads,
        )
        status.header.stamp = stamp
        status.header.frame_id = self.config.map_frame
        self._status_pub.publish(status)


def main() -> None:
    rospy.init_node("block_map_server")
    try:
        BlockMapServer(read_config())
    except UserError as err:
        rospy.logfatal(f"block_map_server: {err}")
        sys.exit(2)
    rospy.spin()
