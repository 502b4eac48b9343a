"""Messages of grid_puzzle_map_provider: poses in, converted to the pure window types, and tile deltas and
status out, built from the pure window and store types."""

from __future__ import annotations

import math

import numpy as np
import rospy
from std_msgs.msg import Header

from grid_puzzle_localization.msg import ProviderStatus, TileDelta
from grid_puzzle_localization.provider.tile_store import StoreStats
from grid_puzzle_localization.provider.window import PoseSample, Window
from grid_puzzle_localization.ros.msgs.streamed import StreamedTileDelta
from grid_puzzle_localization.tiles.grid import tile_stem

Key = tuple[int, int]


def yaw_of(q) -> float | None:
    """Yaw [rad] of a geometry_msgs/Quaternion; None when it is all zeros (orientation not set)."""
    if q.x == q.y == q.z == q.w == 0.0:
        return None
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose_sample(pose, stamp: rospy.Time, twist=None) -> PoseSample:
    """PoseSample of a geometry_msgs/Pose; a body-frame twist becomes a map-frame velocity."""
    yaw = yaw_of(pose.orientation)
    velocity = None
    if twist is not None and yaw is not None:
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy = twist.linear.x, twist.linear.y
        velocity = (c * vx - s * vy, s * vx + c * vy)
    return PoseSample(pose.position.x, pose.position.y, stamp.to_sec(), yaw, velocity)


def tile_delta(
    header: Header,
    revision: int,
    reset: bool,
    s: float,
    window: Window,
    added: list[tuple[Key, np.ndarray]],
    removed: list[Key],
) -> TileDelta:
    """A TileDelta whose added clouds are serialised straight from the tile arrays (msgs/streamed.py).
    The clouds are dense: the tile reader keeps only points with finite x, y, z."""
    i_min, i_max, j_min, j_max = window.bounds
    return StreamedTileDelta(
        [points for _, points in added],
        True,
        header=header,
        revision=revision,
        reset=reset,
        grid_size=s,
        added_ids=[tile_stem(i, j, s) for (i, j), _ in added],
        removed_ids=[tile_stem(i, j, s) for i, j in removed],
        i_min=i_min,
        i_max=i_max,
        j_min=j_min,
        j_max=j_max,
    )


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
