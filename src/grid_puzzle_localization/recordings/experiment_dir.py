"""A recording (scans, poses, times) written as an experiment directory in the layout `gpm simulate`
writes, so that `gpm experiment DIR` runs on it unchanged:

- ``recording.bag``: the played scans on the points topic (stamped with their times, recorded at them)
  and ``/tf_static`` (base -> lidar);
- ``global_map.pcd``: the mapped scans placed by their poses, through a centroid voxel filter (or a copy
  of the user's map);
- ``ground_truth.tum``: the reference poses of the base frame from the first played scan on;
- ``scenario.yaml``: where it all came from and what was selected, dropped and cut.

The directory is built beside the target and renamed into place when complete.
"""

from __future__ import annotations

import os
import shutil
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation import trajectory as tum
from grid_puzzle_localization.pcd import PcdStreamWriter, read_pcd_header
from grid_puzzle_localization.recordings.poses import check_times, guess_format, read_poses, read_times
from grid_puzzle_localization.recordings.scans import read_scan, scan_files
from grid_puzzle_localization.recordings.selection import Plan, Selection, plan
from grid_puzzle_localization.sim.mapping import MAP_DTYPE, VoxelMap
from grid_puzzle_localization.util.atomic import atomic_directory, check_output_dir

FILES = ("scenario.yaml", "ground_truth.tum", "recording.bag", "global_map.pcd")


@dataclass(frozen=True)
class ImportConfig:
    """Parameters of ``gpm import``. Poses map base-frame points into the map frame; scans are in the
    lidar frame, ``extrinsic`` (x y z qx qy qz qw) being base -> lidar."""

    scans: Path
    poses: Path
    times: Path | None = None  # one time a line [s]; None: the TUM pose file's times
    pose_format: str | None = None  # kitti | tum | matrix; None: from the first line
    selection: Selection = field(default_factory=Selection)
    map_file: Path | None = None  # use this map instead of building one from scans
    map_voxel: float = 0.2  # [m] centroid voxel filter of the built map
    extrinsic: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    topic: str = "points"
    map_frame: str = "map"
    base_frame: str = "base_link"
    lidar_frame: str = "lidar"


@dataclass(frozen=True)
class ImportSummary:
    directory: Path
    scans_played: int
    scans_dropped: int
    scans_cut: int
    map_scans: int
    map_points: int
    duration_s: float


def _inputs(cfg: ImportConfig) -> tuple[list[Path], np.ndarray, np.ndarray]:
    """Scan files, poses and times, checked against each other."""
    files = scan_files(cfg.scans)
    fmt = cfg.pose_format or guess_format(cfg.poses)
    poses, pose_times = read_poses(cfg.poses, fmt)
    if cfg.times is not None:
        times = read_times(cfg.times)
        source = cfg.times
    elif pose_times is not None:
        times, source = pose_times, cfg.poses
    else:
        raise UserError(f"{cfg.poses} ({fmt}) holds no times; give the scan times with --times FILE (one a line)")
    counts = {"scan files": len(files), "poses": len(poses), "times": len(times)}
    if len(set(counts.values())) > 1:
        needed = cfg.selection.last
        listing = ", ".join(f"{n} {what}" for what, n in counts.items())
        if needed is None or needed >= min(counts.values()):
            raise UserError(
                f"{listing} ({cfg.scans}, {cfg.poses}, {source}): the counts must agree, pose k and time k"
                f" belonging to the k-th scan file in name order; fix the files, or use only the first scans"
                f" with --last (below {min(counts.values())})"
            )
    n = min(counts.values())
    check_times(times[:n], source)
    return files[:n], poses[:n], times[:n]


def _extrinsic(values: tuple[float, ...]) -> np.ndarray:
    if len(values) != 7 or not np.isfinite(values).all() or not np.linalg.norm(values[3:]) > 0:
        raise UserError(f"--extrinsic needs 7 finite numbers x y z qx qy qz qw, a non-zero quaternion (got {values})")
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_quat(values[3:]).as_matrix()
    pose[:3, 3] = values[:3]
    return pose


def _progress(total: int, desc: str, show: bool) -> tqdm:
    return tqdm(total=total, desc=desc, unit="scan", file=sys.stderr, disable=not show, mininterval=1.0)


def _write_map(path: Path, cfg: ImportConfig, files: list[Path], poses: np.ndarray, p: Plan, show: bool) -> int:
    """Builds the map from the planned scans (or copies the user's map); returns its point count."""
    if cfg.map_file is not None:
        points = read_pcd_header(cfg.map_file).points  # refuses what is not a PCD file
        shutil.copyfile(cfg.map_file, path)
        return points
    if not (0.01 <= cfg.map_voxel <= 5.0):
        raise UserError(f"--map-voxel must be between 0.01 and 5 m (got {cfg.map_voxel})")
    voxels = VoxelMap(cfg.map_voxel)
    base_lidar = _extrinsic(cfg.extrinsic)
    with _progress(len(p.mapped), "map", show) as bar:
        for k in p.mapped:
            scan = read_scan(files[k])
            xyz = np.stack([scan["x"], scan["y"], scan["z"]], axis=1).astype(np.float64)
            pose = poses[k] @ base_lidar
            intensity = scan["intensity"] if "intensity" in (scan.dtype.names or ()) else np.zeros(len(scan))
            voxels.add(xyz @ pose[:3, :3].T + pose[:3, 3], intensity)
            bar.update()
    with PcdStreamWriter(path, MAP_DTYPE) as writer:
        for chunk in voxels.chunks():
            writer.append(chunk)
        return writer.points


def _stamps_ns(times: np.ndarray) -> np.ndarray:
    return np.round(times * 1e9).astype(np.int64)


def _write_bag(path: Path, cfg: ImportConfig, files: list[Path], times: np.ndarray, p: Plan, show: bool) -> None:
    from grid_puzzle_localization.ros.bags.writer import BagNames, ScenarioBag

    names = BagNames(
        points_topic=cfg.topic, map_frame=cfg.map_frame, base_frame=cfg.base_frame, lidar_frame=cfg.lidar_frame
    )
    stamps = _stamps_ns(times)
    with ScenarioBag(str(path), names) as bag, _progress(len(p.played), "bag", show) as bar:
        bag.write_tf_static(stamps[p.played[0]] * 1e-9, np.array(cfg.extrinsic[:3]), np.array(cfg.extrinsic[3:]))
        for k in p.played:
            bag.write_points(int(stamps[k]), int(stamps[k]), read_scan(files[k]))
            bar.update()


def _write_ground_truth(path: Path, poses: np.ndarray, times: np.ndarray, p: Plan) -> None:
    k = p.used[times[p.used] >= times[p.played[0]]]
    quat = Rotation.from_matrix(poses[k, :3, :3]).as_quat()
    truth = tum.make_trajectory(times[k], poses[k, :3, 3], quat, source="reference poses")
    tum.write_tum(path, truth, _stamps_ns(times[k]))


def _describe(cfg: ImportConfig, files: list[Path], times: np.ndarray, poses: np.ndarray, p: Plan) -> dict:
    played = p.played
    steps = np.linalg.norm(np.diff(poses[played, :3, 3], axis=0), axis=1)
    config = asdict(cfg)
    config.pop("selection")
    return {
        "scenario": "import",
        "source": {k: (str(v) if isinstance(v, Path) else v) for k, v in config.items() if not isinstance(v, tuple)},
        "parameters": {
            **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg.selection).items()},
            "gaps": [list(g) for g in cfg.selection.gaps],
        },
        "mount_base_link_to_lidar": {
            "translation_m": [float(v) for v in cfg.extrinsic[:3]],
            "quaternion_xyzw": [float(v) for v in cfg.extrinsic[3:]],
        },
        "localization_run": {
            "duration_s": float(times[played[-1]] - times[played[0]]),
            "length_m": round(float(steps.sum()), 3),
            "start_time_s": float(times[played[0]]),
            "scans_played": len(played),
            "scans_dropped": [files[k].name for k in p.dropped],
            "scans_cut": [files[k].name for k in p.cut],
            "longest_time_between_scans_s": float(np.diff(times[played]).max()),
        },
        "mapping_run": {"scans": [files[k].name for k in p.mapped] if len(p.mapped) else "given map"},
        "frames": {"map": cfg.map_frame, "base": cfg.base_frame, "lidar": cfg.lidar_frame},
        "topics": {"points": cfg.topic, "tf_static": "/tf_static"},
        "files": list(FILES),
    }


def import_recording(cfg: ImportConfig, out_dir: str | os.PathLike, force: bool = False, progress: bool = True):
    """Writes the experiment directory ``out_dir`` (absent or empty, or replaced with ``force``)."""
    out = Path(out_dir).absolute()
    inputs = [cfg.scans, cfg.poses] + [p for p in (cfg.times, cfg.map_file) if p is not None]
    check_output_dir(out, force, inputs)
    _extrinsic(cfg.extrinsic)
    files, poses, times = _inputs(cfg)
    p = plan(cfg.selection, times)
    with atomic_directory(out, durable=True) as tmp:
        map_points = _write_map(tmp / "global_map.pcd", cfg, files, poses, p, progress)
        _write_bag(tmp / "recording.bag", cfg, files, times, p, progress)
        _write_ground_truth(tmp / "ground_truth.tum", poses, times, p)
        description = _describe(cfg, files, times, poses, p)
        (tmp / "scenario.yaml").write_text(yaml.safe_dump(description, sort_keys=False))
    return ImportSummary(
        out,
        len(p.played),
        len(p.dropped),
        len(p.cut),
        len(p.mapped),
        map_points,
        description["localization_run"]["duration_s"],
    )
