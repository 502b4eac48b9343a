"""Scans from a directory of keyframe PCDs and a TUM pose file.

The PCD files (points in the sensor frame) are taken in file-name order, natural for numbers (so
``2.pcd`` comes before ``10.pcd``), and paired one-to-one with the lines of the pose file, which give
``T_map_robot`` of each keyframe.
"""

from __future__ import annotations

import os
from pathlib import Path

from grid_puzzle_localization.blocks.keyframes import Scan
from grid_puzzle_localization.blocks.poses import read_tum
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd, xyz_array
from grid_puzzle_localization.recordings.scans import natural_key


def pcd_keyframe_scans(directory: str | os.PathLike, pose_file: str | os.PathLike) -> list[Scan]:
    directory = Path(directory)
    if not directory.is_dir():
        raise UserError(f"keyframe directory {directory} does not exist; give a directory of .pcd files")
    files = sorted(directory.glob("*.pcd"), key=natural_key)
    if not files:
        raise UserError(f"keyframe directory {directory} holds no .pcd files")
    trajectory = read_tum(pose_file)
    if len(trajectory) != len(files):
        raise UserError(
            f"{pose_file} has {len(trajectory)} poses but {directory} has {len(files)} .pcd files; "
            "the pose file needs one line per keyframe, in file-name order"
        )
    return [
        Scan(float(trajectory.stamps[k]), trajectory.pose(k), lambda f=f: xyz_array(read_pcd(f).points))
        for k, f in enumerate(files)
    ]
