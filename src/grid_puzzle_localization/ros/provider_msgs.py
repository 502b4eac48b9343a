"""Messages of grid_puzzle_map_provider built from the pure window and store types."""

from __future__ import annotations

import math

import numpy as np
import rospy
from std_msgs.msg import Header

from grid_puzzle_localization.grid import tile_stem
from grid_puzzle_localization.msg import ProviderStatus, TileDelta
from grid_puzzle_localization.ros.cloud_msg import array_to_cloud
from grid_puzzle_localization.tile_store import StoreStats
from grid_puzzle_localization.window import Window

Key = tuple[int, int]


def tile_delta(
    header: Header,
    revision: int,
    reset: bool,
    s: float,
    window: Window,
    added: list[tuple[Key, np.ndarray]],
    removed: list[Key],
) -> TileDelta:
    msg = TileDelta(header=header, revision=revision, reset=reset, grid_size=s)
    msg.added_ids = [tile_stem(i, j, s) for (i, j), _ in added]
    msg.added_clouds = [
        array_to_cloud(points, header=Header(frame_id=header.frame_id, stamp=header.stamp)) for _, points in added
    ]
    msg.removed_ids = [tile_stem(i, j, s) for i, j in removed]
    msg.i_min, msg.i_max, msg.j_min, msg.j_max = window.bounds
    return msg


def provider_status(
    header: Header, window: Window, stats: StoreStats, load_ms: float, update_ms: float
) -> ProviderStatus:
    msg = ProviderStatus(header=header)
    msg.i_min, msg.i_max, msg.j_min, msg.j_max = window.bounds
    msg.theta = window.theta if math.isfinite(window.theta) else math.nan
    msg.sector = window.sector
    msg.tiles_loaded = stats.tiles_loaded
    msg.points = stats.points
    msg.bytes = stats.bytes
    msg.load_ms = load_ms
    msg.update_ms = update_ms
    msg.cache_hits = stats.cache_hits
    msg.cache_misses = stats.cache_misses
    msg.corrupt_tiles = list(stats.corrupt)
    return msg


def stamped(frame_id: str, stamp: rospy.Time | None = None) -> Header:
    return Header(frame_id=frame_id, stamp=stamp if stamp is not None else rospy.Time.now())
