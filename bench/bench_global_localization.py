#!/usr/bin/env python3
"""`make bench-global-localization`: global localization (branch-and-bound search + NDT, the C++
``global_localize`` program) against known poses. Prints one JSON line per data set and search mode.

Data sets:
- sim_courtyard, sim_urban: a world of `gpm simulate` at --scale, its prior map built from sweeps every
  --keyframe-spacing metres of the mapping run (with the simulated drift of its pose estimate), and single sweeps
  simulated at random poses of the localization route; base frame = lidar frame, truth = the simulator's pose;
- mulran_riverside02: real Ouster OS1-64 keyframes, scans 50-215 ($GPL_SHARED_DATA or ../shared/data/real beside
  the clone), with the FAST-LIO2 odometry as the reference (not ground truth: the reference mode shows where it
  disagrees with the map, and tools/reference_check.py where it disagrees with the motion between the scans; the
  success rate is also given over the trials whose scan's reference agrees with both neighbours). The map is built
  from the even-numbered scans, the odd-numbered ones are localized;
- kitti_campus: real Velodyne HDL-64E keyframes of kitti00_far's first stretch with their OXTS GNSS/INS poses, the
  map from every 3rd scan (`gpm import`, as `make experiment-real`) set inside the real 0.9 km^2 Nova campus map
  (tools/experiment_tracking.py campus_map()), the other scans localized: the map a start without a pose searches;
- quick (--quick): a tiny synthetic street (fixtures.synthetic_scene), a few seconds in all.
Each trial rotates the scan by a random yaw and centres the search up to --offset m away from the truth in a
random direction. Success: accepted and within 0.3 m and 1 deg of the truth. Modes: the default search
(adapted initial score S0) on a --size square, the plain BBS (no S0) on the same, and the default search on a
--large-size square, all over the full circle of yaw; "whole", the default search over the square that holds the
whole map (its centre and longer side: the localizer's start without a pose); and "reference", the refinement
started at the true pose, whose error says how well the reference pose fits the map at all (a bound on what any
search can reach).
Times: wall seconds of each search and its CPU seconds (all threads), which a busy machine inflates less.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np
from hardware import cpu_model

from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array, xyz_records

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from experiment_tracking import CAMPUS, KITTI, STRETCHES, VARIANTS, campus_map, write_scenario  # noqa: E402
from reference_check import cached_check  # noqa: E402
from shared_data import SHARED_REAL_DATA  # noqa: E402

MULRAN = SHARED_REAL_DATA / "mulran_riverside02"
MULRAN_SCANS = range(50, 216)
SUCCESS_M, SUCCESS_DEG = 0.3, 1.0


class Trial:
    """One search: the scan file (base frame), the true map_T_base (4x4), the search centre and, for a reference
    that is not ground truth, whether it agrees with the scans around (None: not checked)."""

    def __init__(self, scan: Path, truth: np.ndarray, center: tuple[float, float]) -> None:
        self.scan, self.truth, self.center = scan, truth, center
        self.trusted: bool | None = None


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def make_trial(directory: Path, name: str, points: np.ndarray, truth: np.ndarray, offset: float, rng) -> Trial:
    """Writes ``points`` (scan frame) turned by a random yaw; the truth turns with it."""
    turn = yaw_matrix(rng.uniform(-math.pi, math.pi))
    scan = directory / f"{name}.pcd"
    write_pcd(scan, xyz_records((points @ turn[:3, :3].T).astype(np.float32)))
    angle, distance = rng.uniform(-math.pi, math.pi), offset * math.sqrt(rng.uniform())
    center = (truth[0, 3] + distance * math.cos(angle), truth[1, 3] + distance * math.sin(angle))
    return Trial(scan, truth @ np.linalg.inv(turn), center)


def pose_matrix(answer: dict) -> np.ndarray:
    """map_T_base from x y z roll pitch yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    cr, sr = math.cos(answer["roll"]), math.sin(answer["roll"])
    cp, sp = math.cos(answer["pitch"]), math.sin(answer["pitch"])
    cy, sy = math.cos(answer["yaw"]), math.sin(answer["yaw"])
    m = np.eye(4)
    m[:3, :3] = (
        np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    )
    m[:3, 3] = answer["x"], answer["y"], answer["z"]
    return m


def errors(answer: dict, truth: np.ndarray) -> tuple[float, float]:
    """Translation [m] and rotation [deg] error."""
    delta = np.linalg.inv(truth) @ pose_matrix(answer)
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(delta[:3, :3]) - 1) / 2))))
    return float(np.linalg.norm(delta[:3, 3])), angle


def whole_square(map_pcd: Path) -> tuple[tuple[float, float], float]:
    """The centre and side [m] of the square that holds the map's x y extent."""
    xy = xyz_array(read_pcd(map_pcd).points)[:, :2]
    low, high = xy.min(axis=0), xy.max(axis=0)
    return (float(0.5 * (low[0] + high[0])), float(0.5 * (low[1] + high[1]))), float((high - low).max())


def search(
    program: Path,
    map_pcd: Path,
    trials: list[Trial],
    size: float,
    threads: int,
    plain: bool,
    overrides: list[str],
    centre: tuple[float, float] | None = None,
) -> list[dict]:
    """Each trial searched over the full circle of yaw in a square of ``size`` [m] around its centre (or around
    ``centre`` for all); ``size`` 0: the reference check, a 1 m square and +-0.05 rad around the true pose (the
    refinement from the truth)."""
    with tempfile.NamedTemporaryFile("w", suffix=".txt") as requests:
        for t in trials:
            if size > 0:
                x, y = centre or t.center
                requests.write(f"{t.scan} {x!r} {y!r} {size!r} 0 {2 * math.pi!r}\n")
            else:
                yaw = math.atan2(t.truth[1, 0], t.truth[0, 0])
                requests.write(f"{t.scan} {t.truth[0, 3]!r} {t.truth[1, 3]!r} 1.0 {yaw!r} 0.1\n")
        requests.flush()
        cmd = [str(program), "--map", str(map_pcd), "--requests", requests.name, "--threads", str(threads)]
        cmd += [arg for o in overrides for arg in ("--set", o)]
        out = subprocess.run(cmd + (["--plain"] if plain else []), check=True, capture_output=True, text=True)
    return [json.loads(line) for line in out.stdout.splitlines()]


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def scored(answers: list[dict], trials: list[Trial]) -> list[dict]:
    """Each answer with its errors against the truth and whether it counts as a success."""
    out = []
    for k, answer in enumerate(answers):
        error_m, error_deg = errors(answer, trials[k].truth)
        ok = answer["found"] and error_m <= SUCCESS_M and error_deg <= SUCCESS_DEG
        out.append({**answer, "error_m": error_m, "error_deg": error_deg, "success": ok})
    return out


def refusal_kind(reason: str) -> str:
    """A refusal's reason without its figures, so that refusals of one kind count together."""
    return re.sub(r"\d[\d.e+-]*", "#", reason.split(":")[0].split(" (")[0])


def summary(
    dataset: str, mode: str, size: float, threads: int, rows: list[dict], reference_ok: list[bool] | None, trials
) -> dict:
    """``reference_ok``: per trial, whether the refinement from the reference pose met the success criterion
    (None when the reference mode did not run); the success rate over those trials is what a search can reach
    against a reference that disagrees with the map elsewhere. Trials whose ``trusted`` is set also give the
    success rate over those whose reference agrees with the motion between the scans."""
    accepted = [r for r in rows if r["found"]]
    consistent = [r for k, r in enumerate(rows) if reference_ok is not None and reference_ok[k]]
    checked = [t.trusted is not None for t in trials]
    trusted = [r for r, t in zip(rows, trials) if t.trusted]
    return {
        "dataset": dataset,
        "mode": mode,
        "search_size_m": size,
        "yaw_range_deg": 360.0,
        "threads": threads,
        "trials": len(rows),
        "success_rate": sum(r["success"] for r in rows) / len(rows),
        "trials_where_reference_fits": len(consistent) if reference_ok is not None else None,
        "success_rate_where_reference_fits": (
            sum(r["success"] for r in consistent) / len(consistent) if consistent else None
        ),
        "trials_where_reference_trusted": len(trusted) if any(checked) else None,
        "success_rate_where_reference_trusted": (
            sum(r["success"] for r in trusted) / len(trusted) if trusted else None
        ),
        "refused": len(rows) - len(accepted),
        "accepted_wrong": sum(not r["success"] for r in accepted),
        "median_seconds": percentile([r["seconds"] for r in rows], 50),
        "p95_seconds": percentile([r["seconds"] for r in rows], 95),
        "median_translation_error_m": percentile([r["error_m"] for r in accepted], 50),
        "median_rotation_error_deg": percentile([r["error_deg"] for r in accepted], 50),
        "median_cpu_seconds": percentile([r["cpu_seconds"] for r in rows], 50),
        "p95_cpu_seconds": percentile([r["cpu_seconds"] for r in rows], 95),
        # Where the wall time goes (medians): likelihood grids + pyramid, branch and bound, NDT refinement.
        "median_grid_seconds": percentile([r["grid_seconds"] for r in rows], 50),
        "median_search_seconds": percentile([r["search_seconds"] for r in rows], 50),
        "median_refine_seconds": percentile([r["refine_seconds"] for r in rows], 50),
        "median_candidates": percentile([r["candidates_evaluated"] for r in rows], 50),
        "refusals": dict(Counter(refusal_kind(r["reason"]) for r in rows if not r["found"])),
    }


# ---------------------------------------------------------------- data sets


def quick_dataset(directory: Path, trials: int, offset: float, rng) -> tuple[Path, list[Trial]]:
    from fixtures import synthetic_scene as ss

    scene = ss.make_scene(length=60.0)
    map_pcd = directory / "map.pcd"
    write_pcd(map_pcd, xyz_records(ss.sample_map(scene, spacing=0.3)))
    out = []
    for k in range(trials):
        base = ss.pose_matrix(np.array([rng.uniform(0, 50), rng.uniform(-2, 2), 0.0]), rng.uniform(-math.pi, math.pi))
        points = ss.scan(scene, base, rng)
        out.append(make_trial(directory, f"quick_{k}", points, base @ ss.lidar_mount(), offset, rng))
    return map_pcd, out


def sim_dataset(world_name: str, scale: float, spacing: float, directory: Path, trials: int, offset: float, rng):
    """The prior map: sweeps every ``spacing`` [m] of the scenario's mapping run, placed (and deskewed) with its
    drifted pose estimate, voxel-filtered like `gpm simulate`'s map (whose every-sweep map takes too long here)."""
    from grid_puzzle_localization.pcd import PcdStreamWriter
    from grid_puzzle_localization.sim.lidar import Mount, SweepSimulator
    from grid_puzzle_localization.sim.mapping import MAP_DTYPE, VoxelMap, drifted, to_map
    from grid_puzzle_localization.sim.raycast import RayCaster
    from grid_puzzle_localization.sim.scenario import MOUNTS, ScenarioConfig, _rng
    from grid_puzzle_localization.sim.sensors import get_sensor
    from grid_puzzle_localization.sim.trajectory import RATE, Trajectory, localization_trajectory, mapping_trajectory
    from grid_puzzle_localization.sim.worlds import make_world

    cfg = ScenarioConfig(world=world_name, scale=scale).resolved()
    world = make_world(cfg.world, cfg.seed, cfg.scale)
    loc = localization_trajectory(world, cfg.scale, _rng(cfg.seed, 1))
    mapping = mapping_trajectory(world, loc, _rng(cfg.seed, 2))
    estimate = drifted(mapping, cfg.drift, _rng(cfg.seed, 3))
    mount = Mount(np.array(MOUNTS[cfg.world]), np.eye(3))
    base_t_lidar = np.eye(4)
    base_t_lidar[:3, :3], base_t_lidar[:3, 3] = mount.rotation, mount.translation
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(mapping.position[:, :2], axis=0), axis=1))])
    keyframes = np.searchsorted(travelled, np.arange(0.0, travelled[-1], spacing)) / RATE
    map_pcd = directory / f"{world_name}_map.pcd"
    out = []
    with RayCaster(world.mesh, threads=2) as caster:
        sim = SweepSimulator(world.mesh, caster, get_sensor(cfg.sensor), mount)
        voxels = VoxelMap(cfg.map_leaf)
        for k, t in enumerate(keyframes):
            cloud = sim.simulate(mapping, float(t), sim.sensor.sweep(k), rng)
            voxels.add(to_map(estimate, mount, float(t), cloud), cloud["intensity"])
        with PcdStreamWriter(map_pcd, MAP_DTYPE) as writer:
            for chunk in voxels.chunks():
                writer.append(chunk)
        for k in range(trials):
            pos, quat = loc.interpolate(np.array([rng.uniform(0.0, loc.duration)]))
            still = Trajectory(np.repeat(pos, 2, axis=0), np.repeat(quat, 2, axis=0), loc.route)
            cloud = sim.simulate(still, 0.0, sim.sensor.sweep(k), rng)
            base = np.eye(4)
            base[:3, :3], base[:3, 3] = still.frames(np.zeros(1))[1][:, :, 0], pos[0]
            out.append(make_trial(directory, f"{world_name}_{k}", xyz_array(cloud), base @ base_t_lidar, offset, rng))
    return map_pcd, out


def mulran_dataset(directory: Path, trials: int, offset: float, rng) -> tuple[Path, list[Trial]]:
    poses = np.loadtxt(MULRAN / "odom_poses.txt").reshape(-1, 3, 4)

    def pose(k: int) -> np.ndarray:
        return np.vstack([poses[k], [0.0, 0.0, 0.0, 1.0]])

    def scan(k: int) -> np.ndarray:
        points = xyz_array(read_pcd(MULRAN / "Scans" / f"{k:06d}.pcd").points)
        return points[np.isfinite(points).all(axis=1)]

    parts = []
    for k in MULRAN_SCANS:
        if k % 2 == 0:
            p = scan(k)
            parts.append(p @ pose(k)[:3, :3].T + pose(k)[:3, 3])
    map_pcd = directory / "mulran_map.pcd"
    write_pcd(map_pcd, xyz_records(np.concatenate(parts).astype(np.float32)))
    held = [k for k in MULRAN_SCANS if k % 2 == 1]
    first, last = MULRAN_SCANS[0], MULRAN_SCANS[-1]
    _, trusted = cached_check(
        MULRAN / "Scans", MULRAN / "odom_poses.txt", first, last, ROOT / "build" / "reference_check"
    )
    out = []
    for n in range(trials):
        k = held[n % len(held)]
        out.append(make_trial(directory, f"mulran_{n}", scan(k), pose(k), offset, rng))
        out[-1].trusted = k in trusted
    return map_pcd, out


def kitti_campus_dataset(directory: Path, trials: int, offset: float, rng) -> tuple[Path, list[Trial]]:
    first, last, _ = STRETCHES["s1"]
    variant = VARIANTS["kitti_s1_none_campus"]
    stretch = directory / variant.scenario
    write_scenario(variant, stretch, stdout=subprocess.DEVNULL)  # stdout holds only the JSON lines
    map_pcd = campus_map(stretch / "global_map.pcd", directory / "kitti_campus_map.pcd")
    poses = np.loadtxt(KITTI / "poses_kitti.txt").reshape(-1, 3, 4)
    files = sorted((KITTI / "scans").glob("*.pcd"))
    held = [k for k in range(first, last + 1) if (k - first) % 3 != 0]  # the scans the map was not built from
    out = []
    for n in range(trials):
        k = held[(n * len(held)) // trials] if trials <= len(held) else held[n % len(held)]
        points = xyz_array(read_pcd(files[k]).points)
        out.append(make_trial(directory, f"kitti_{n}", points, np.vstack([poses[k], [0, 0, 0, 1]]), offset, rng))
    return map_pcd, out


# ---------------------------------------------------------------- main


def find_program() -> Path:
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh (the Makefile sources it)
    return workspace / "devel/lib/grid_puzzle_localization/global_localize"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="a tiny synthetic street only (a few seconds)")
    parser.add_argument("--trials", type=int, default=100, help="trials per data set (default 100)")
    parser.add_argument(
        "--datasets", default="sim_courtyard,sim_urban,mulran_riverside02,kitti_campus", help="comma-separated"
    )
    parser.add_argument("--scale", type=float, default=0.25, help="simulated world scale (default 0.25)")
    parser.add_argument("--keyframe-spacing", type=float, default=2.0, help="simulated map: a sweep every ... [m]")
    parser.add_argument("--size", type=float, default=40.0, help="search square [m] (default 40)")
    parser.add_argument("--large-size", type=float, default=100.0, help="the larger search square [m] (default 100)")
    parser.add_argument("--offset", type=float, default=15.0, help="largest distance of the centre from the truth [m]")
    parser.add_argument("--threads", type=int, default=2, help="OpenMP threads (default 2)")
    parser.add_argument(
        "--modes",
        default="reference,s0,plain,large,whole",
        help="comma-separated: reference (refinement from the true pose: how well the reference fits the map), s0,"
        " plain, large, whole (default: all)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="NAME=V", help="search parameter override")
    parser.add_argument("--per-trial", action="store_true", help="also print one JSON line per trial")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--exe", type=Path, default=None, help="global_localize program (default: the workspace's)")
    args = parser.parse_args()
    program = args.exe or find_program()
    hardware = {"cpu_model": cpu_model(), "cores": os.cpu_count()}
    datasets = ["quick"] if args.quick else args.datasets.split(",")
    trials = 4 if args.quick else args.trials
    modes = {
        "s0": (args.size, False),
        "plain": (args.size, True),
        "large": (args.large_size, False),
        "whole": (None, False),
        "reference": (0.0, False),
    }
    chosen = ["s0"] if args.quick else args.modes.split(",")
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        for dataset in datasets:
            directory = Path(tmp)
            if dataset == "quick":
                map_pcd, data = quick_dataset(directory, trials, args.offset, rng)
            elif dataset.startswith("sim_"):
                map_pcd, data = sim_dataset(
                    dataset[4:], args.scale, args.keyframe_spacing, directory, trials, args.offset, rng
                )
            elif dataset == "mulran_riverside02":
                if not MULRAN.is_dir():
                    print(json.dumps({"dataset": dataset, "skipped": f"{MULRAN} is absent (set GPL_SHARED_DATA)"}))
                    continue
                map_pcd, data = mulran_dataset(directory, trials, args.offset, rng)
            elif dataset == "kitti_campus":
                if not (KITTI / "scans").is_dir() or not CAMPUS.is_dir():
                    print(json.dumps({"dataset": dataset, "skipped": f"{KITTI} or {CAMPUS} is absent"}))
                    continue
                map_pcd, data = kitti_campus_dataset(directory, trials, args.offset, rng)
            else:
                print(f"unknown data set {dataset!r}", file=sys.stderr)
                return 2
            reference_ok = None
            for mode in chosen:
                size, plain = modes[mode]
                centre = None
                if mode == "whole":
                    centre, size = whole_square(map_pcd)
                answers = search(program, map_pcd, data, size, args.threads, plain, args.set, centre)
                rows = scored(answers, data)
                if args.per_trial:
                    for r in rows:
                        print(json.dumps({"dataset": dataset, "mode": mode, **r}))
                if mode == "reference":
                    reference_ok = [r["success"] for r in rows]
                row = summary(dataset, mode, size, args.threads, rows, reference_ok, data)
                row.update(hardware, load_average_1min=os.getloadavg()[0], overrides=args.set)
                print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
