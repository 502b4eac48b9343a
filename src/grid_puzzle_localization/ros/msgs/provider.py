"""Messages of grid_puzzle_map_provider: poses in, converted to the pure window types, and tile deltas and
status out, built from the pure window and tile reference types. Tile deltas carry tiles by reference
(names and their directory), never points."""

from __future__ import annotations

import math

import rospy
from std_msgs.msg import Header

from grid_puzzle_localization.msg import ProviderStatus, TileDelta
from grid_puzzle_localization.provider.tile_references import Key
from grid_puzzle_localization.provider.window import PoseSample, Window
from grid_puzzle_localization.tiles.grid import tile_stem


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
    tile_dir: str,
    index_revision: str,
    added: list[Key],
    removed: list[Key],
    prefetch: list[Key],
) -> TileDelta:
    """A TileDelta by reference: the localizer reads ``tile_dir``/<id>.pcd itself."""
    i_min, i_max, j_min, j_max = window.bounds

    def stems(keys: list[Key]) -> list[str]:
        return [tile_stem(i, j, s) for i, j in keys]

    return TileDelta(
        header=header,
        revision=revision,
        reset=reset,
        grid_size=s,
        tile_dir=tile_dir,
        index_revision=index_revision,
        added_ids=stems(added),
        removed_ids=stems(removed),
        prefetch_ids=stems(prefetch),
        i_min=i_min,
        i_max=i_max,
        j_min=j_min,
        j_max=j_max,
    )


def provider_status(
    header: Header, window: Window, delta: TileDelta, tiles_loaded: int, update_ms: float
) -> ProviderStatus:
    msg = ProviderStatus(header=header)
    msg.i_min, msg.i_max, msg.j_min, msg.j_max = window.bounds
    msg.theta = window.theta if math.isfinite(window.theta) else math.nan
    msg.sector = window.sector
    msg.tile_dir = delta.tile_dir
    msg.index_revision = delta.index_revision
    msg.tiles_loaded = tiles_loaded
    msg.tiles_added = len(delta.added_ids)
    msg.tiles_removed = len(delta.removed_ids)
    msg.tiles_prefetch = len(delta.prefetch_ids)
    msg.update_ms = update_ms
    msg.store_reachable = True  # a directory; a map store's provider sets its own state
    return msg


def stamped(frame_id: str, stamp: rospy.Time | None = None) -> Header:
    return Header(frame_id=frame_id, stamp=stamp if stamp is not None else rospy.Time.now())
