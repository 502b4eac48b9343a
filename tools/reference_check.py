#!/usr/bin/env python3
"""Where a recording's reference poses agree with its own scans: each pair of consecutive scans is registered by
the core NDT (`ndt_align`, scan k+1 onto scan k) and the motion it finds is compared with the motion the
reference poses give.

SLAM output used as a reference (the MulRan keyframes' FAST-LIO2 odometry) can be metres off where its odometry
slid along a featureless road; a localizer's error against it there is the reference's as much as its own. The
registration uses the scans' structure only: the ground (whose rings around the sensor look the same in every
scan and pull consecutive scans onto each other) and the points within MIN_RANGE_M are left out. It starts from the
reference's motion scaled by 0, 0.5, 1 and 1.5 (so a reference that overstates or reverses the motion does not
choose the answer) and keeps the best fit (NVTL); when another start ends more than MAX_SHIFT_M away with a fit
within AMBIGUOUS_RATIO of the best, the scans cannot tell the motion (a featureless road) and the pair is
*ambiguous*. A pair is *consistent* when the registration converged, fits (NVTL >= MIN_NVTL), is not ambiguous and
lies within MAX_SHIFT_M and MAX_TURN_DEG of the reference's motion. A scan's reference is *trusted* when both pairs
it belongs to are consistent.

With --map MAP.pcd (a map built from the same reference poses, e.g. `gpm import`'s global_map.pcd) it checks the
reference against that map instead: each scan, its ground kept, is registered onto the map from its reference pose,
and the row says how far the map moves it (`map_shift_m`, `map_turn_deg`). Where the reference is bent, the map
built from it is bent too, and a scan's own reference pose can lie a metre from where that map holds it.

Usage: reference_check.py SCANS_DIR POSES.kitti FIRST LAST [--json OUT] [--map MAP.pcd]  (prints one JSON line per
pair, or per scan with --map, and a summary line; needs the built workspace for ndt_align)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.pcd.writer import write_pcd
from grid_puzzle_localization.recordings.poses import read_poses
from grid_puzzle_localization.recordings.scans import read_scan, scan_files
from grid_puzzle_localization.util.atomic import atomic_write

NDT_ALIGN = Path(os.environ.get("GPL_WS", "")) / "devel/lib/grid_puzzle_localization/ndt_align"
STARTS = (0.0, 0.5, 1.0, 1.5)  # scale factors of the reference's translation the registration starts from
MIN_NVTL = 0.5  # the localizer's match/min_nvtl default
MAX_SHIFT_M = 0.3  # [m] registration and reference motion agree within this ...
MAX_TURN_DEG = 0.5  # [deg] ... and this
AMBIGUOUS_RATIO = 0.98  # another answer fitting this well (NVTL ratio) makes the pair ambiguous
MIN_RANGE_M = 3.0  # [m] points closer to the sensor are left out (the vehicle itself)
ABOVE_GROUND_M = 0.5  # [m] points less than this above the scan's ground (its lowest 5 % of heights) are left out


def structure(scan: Path, out: Path) -> Path:
    """Writes the x y z of ``scan``'s structure points (no ground, nothing near the sensor) to ``out``."""
    points = read_scan(scan)
    xyz = np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float32)
    near = np.linalg.norm(xyz[:, :2], axis=1) < MIN_RANGE_M
    ground = np.percentile(xyz[~near, 2], 5.0) if (~near).any() else 0.0
    keep = xyz[~near & (xyz[:, 2] > ground + ABOVE_GROUND_M)]
    cloud = np.empty(len(keep), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    cloud["x"], cloud["y"], cloud["z"] = keep.T
    write_pcd(out, cloud)
    return out


def register(target: Path, source: Path, guess: np.ndarray) -> dict:
    """ndt_align's answer for ``source`` onto ``target`` from the 4x4 ``guess`` (T_target_source)."""
    rpy = Rotation.from_matrix(guess[:3, :3]).as_euler("xyz")  # fixed-axis roll, pitch, yaw
    pose = [*map(str, guess[:3, 3]), *map(str, rpy)]
    args = [str(NDT_ALIGN), str(target), str(source), "--threads", "1", "--guess", *pose]
    done = subprocess.run(args, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"ndt_align failed on {target.name} <- {source.name}: {done.stderr.strip()}")
    return json.loads(done.stdout)


def check_pair(target: Path, source: Path, reference: np.ndarray) -> dict:
    """The best registration from the scaled starts, and how far it is from the reference motion."""
    answers = []
    for scale in STARTS:
        guess = reference.copy()
        guess[:3, 3] *= scale
        r = register(target, source, guess)
        if r["status"] in ("OK", "MAX_ITERATIONS"):
            answers.append(r)
    if not answers:
        return {"consistent": False, "ambiguous": False, "reason": "no registration"}
    best = max(answers, key=lambda r: r["nvtl"])
    found = np.asarray(best["transform"])
    ambiguous = any(
        r["nvtl"] >= AMBIGUOUS_RATIO * best["nvtl"]
        and np.linalg.norm(np.asarray(r["transform"])[:3, 3] - found[:3, 3]) > MAX_SHIFT_M
        for r in answers
    )
    difference = np.linalg.inv(reference) @ found
    shift = float(np.linalg.norm(difference[:3, 3]))
    turn = float(np.degrees(Rotation.from_matrix(difference[:3, :3]).magnitude()))
    agrees = shift <= MAX_SHIFT_M and turn <= MAX_TURN_DEG
    consistent = bool(best["converged"] and best["nvtl"] >= MIN_NVTL and not ambiguous and agrees)
    return {
        "consistent": consistent,
        "ambiguous": ambiguous,
        "nvtl": round(best["nvtl"], 3),
        "reference_step_m": round(float(np.linalg.norm(reference[:3, 3])), 3),
        "registered_step_m": round(float(np.linalg.norm(found[:3, 3])), 3),
        "shift_m": round(shift, 3),
        "turn_deg": round(turn, 3),
    }


def check(scans_dir: Path, poses_path: Path, first: int, last: int) -> tuple[list[dict], set[int]]:
    """Per pair (k, k+1) for first <= k < last: the check's row; and the scans whose reference is trusted."""
    files = scan_files(scans_dir)
    poses, _ = read_poses(poses_path, "kitti")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        crops = {k: structure(files[k], Path(tmp) / f"{k}.pcd") for k in range(first, last + 1)}
        for k in range(first, last):
            reference = np.linalg.inv(poses[k]) @ poses[k + 1]
            rows.append({"scan": k, "next": k + 1, **check_pair(crops[k], crops[k + 1], reference)})
    consistent = {row["scan"] for row in rows if row["consistent"]}
    trusted = {k for k in range(first + 1, last) if k - 1 in consistent and k in consistent}
    return rows, trusted


def map_shift(map_path: Path, scan: Path, pose: np.ndarray) -> dict:
    """How far the registration of ``scan`` onto ``map_path`` from its reference ``pose`` moves it, and where it puts
    it (``map_pose``, the 4x4 map_T_scan as nested lists)."""
    r = register(map_path, scan, pose)
    fitted = np.asarray(r["transform"])
    difference = np.linalg.inv(pose) @ fitted
    return {
        "status": r["status"],
        "nvtl": round(r["nvtl"], 3),
        "map_shift_m": round(float(np.linalg.norm(difference[:3, 3])), 3),
        "map_turn_deg": round(float(np.degrees(Rotation.from_matrix(difference[:3, :3]).magnitude())), 3),
        "map_pose": fitted.tolist(),
    }


def map_check(scans_dir: Path, poses_path: Path, first: int, last: int, map_path: Path) -> list[dict]:
    """Per scan k in [first, last]: how far the registration onto ``map_path`` from the reference pose moves it."""
    files = scan_files(scans_dir)
    poses, _ = read_poses(poses_path, "kitti")
    return [{"scan": k, **map_shift(map_path, files[k], poses[k])} for k in range(first, last + 1)]


def cached_check(
    scans_dir: Path, poses_path: Path, first: int, last: int, cache_dir: Path
) -> tuple[list[dict], set[int]]:
    """check(), kept in ``cache_dir`` under a name that changes with its inputs (the scans, the poses and
    ndt_align, by path, size and time; the range; the thresholds), so a benchmark and an experiment share one
    run of it (some hundred registrations)."""
    files = [Path(p).resolve() for p in (scans_dir, poses_path, NDT_ALIGN)]
    inputs = [f"{p}:{p.stat().st_size}:{p.stat().st_mtime_ns}" for p in files]
    settings = [first, last, STARTS, MIN_NVTL, MAX_SHIFT_M, MAX_TURN_DEG, AMBIGUOUS_RATIO, MIN_RANGE_M, ABOVE_GROUND_M]
    key = hashlib.sha1(json.dumps([inputs, settings]).encode()).hexdigest()[:16]
    path = Path(cache_dir) / f"reference_check_{key}.json"
    if path.exists():
        data = json.loads(path.read_text())
        return data["rows"], set(data["trusted"])
    rows, trusted = check(scans_dir, poses_path, first, last)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as f:
        json.dump({"trusted": sorted(trusted), "rows": rows}, f)
    return rows, trusted


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scans", type=Path)
    parser.add_argument("poses", type=Path, help="KITTI poses, one line per scan file")
    parser.add_argument("first", type=int)
    parser.add_argument("last", type=int)
    parser.add_argument("--json", type=Path, help="also write the trusted scans and the rows to this file")
    parser.add_argument("--map", type=Path, help="check each scan against this map (built from the same poses)")
    args = parser.parse_args()
    if args.map:
        rows = map_check(args.scans, args.poses, args.first, args.last, args.map)
        for row in rows:
            print(json.dumps(row))
        shifts = [row["map_shift_m"] for row in rows]
        print(
            json.dumps(
                {"scans": len(rows), "max_map_shift_m": max(shifts), "median_map_shift_m": float(np.median(shifts))}
            )
        )
        return 0
    rows, trusted = check(args.scans, args.poses, args.first, args.last)
    for row in rows:
        print(json.dumps(row))
    summary = {
        "pairs": len(rows),
        "consistent_pairs": sum(r["consistent"] for r in rows),
        "ambiguous_pairs": sum(r["ambiguous"] for r in rows),
        "trusted_scans": len(trusted),
    }
    print(json.dumps(summary))
    if args.json:
        args.json.write_text(json.dumps({**summary, "trusted": sorted(trusted), "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
