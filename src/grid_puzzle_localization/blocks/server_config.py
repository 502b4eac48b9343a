"""Parameters of the block map server (the one place their defaults live)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from grid_puzzle_localization.errors import UserError

POSE_TYPES = ("odometry", "pose_with_covariance")


@dataclass(frozen=True)
class BlockMapServerConfig:
    block_dir: str = ""  # directory written by `gpm blocks` or `gpm submaps` (required)
    num_blocks: int = 2  # nearest blocks merged into map_cloud, as in the block map reference implementation
    planar: bool = False  # select by x, y distance only (true) or by 3-D distance to the centroids
    cache_blocks: int = 0  # blocks kept in memory beyond the selection (LRU)
    pose_type: str = "odometry"  # "odometry": nav_msgs/Odometry on `odom`; "pose_with_covariance": on `pose`
    map_frame: str = "map"  # frame_id of map_cloud; incoming poses must be in this frame
    # Start pose [x y z roll pitch yaw] (m, rad; only the position is used) or (): the blocks around it are
    # published at startup, before any pose arrives (the localizer needs a map to publish its first pose).
    initial_pose: tuple[float, ...] = ()

    def checked(self) -> BlockMapServerConfig:
        if not self.block_dir:
            raise UserError("parameter ~block_dir is required: the directory written by `gpm blocks`")
        if self.num_blocks < 1:
            raise UserError(f"parameter ~num_blocks must be >= 1 (got {self.num_blocks})")
        if self.cache_blocks < 0:
            raise UserError(f"parameter ~cache_blocks must be >= 0 (got {self.cache_blocks})")
        if len(self.initial_pose) not in (0, 6) or not all(math.isfinite(v) for v in self.initial_pose):
            raise UserError(f"parameter ~initial_pose must be [] or [x y z roll pitch yaw] (got {self.initial_pose})")
        if self.pose_type not in POSE_TYPES:
            raise UserError(f"parameter ~pose_type must be one of {POSE_TYPES} (got '{self.pose_type}')")
        return self
