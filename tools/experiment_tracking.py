#!/usr/bin/env python3
"""Tracking on real and hard recordings: `make experiment-real` and `make experiment-hard`.

Real (``make experiment-real``): the KITTI odometry 00 keyframes of ../shared/data/real/kitti00_far (or
$GPL_SHARED_DATA): real Velodyne HDL-64E scans of a car, about 2 m apart, with OXTS RTK GNSS/INS poses
(decimetre-level: a reference, not SLAM output). Its two stretches (stretches.txt: lines 0-251 and 252-560 of the
pose and time files) are each imported with `gpm import` (the map from every 3rd scan, the others played), and
run in six variants per stretch ``s1`` and ``s2``:
- ``kitti_s1``: as recorded, started at the first reference pose, each mode run 3 times (interleaved) for the
  medians of its CPU and memory;
- ``kitti_s1_drop20_gap8``: 20 % of the played scans dropped at random and 8 s cut in the middle of the drive;
- ``kitti_s1_offset20_90``: started 20 m off in a seeded random direction and turned by 90 deg;
- ``kitti_s1_hint20``: no start pose, a hint 20 m sigma from the start on initialpose_hint;
- ``kitti_s1_none``: no start pose and no hint: the localizer's global search over its map;
- ``kitti_s1_none_campus``: the same in a map of the size a start without a pose must handle (up to 1 km^2): the
  stretch's map inside the real Nova campus map of ../shared/data/real/nova_utd_tiles (campus_map()).
Grid puzzle mode uses the urban preset's window (n 25, k 20, s 2 m), as a car's scans reach far.

Simulated (``make experiment-hard``): 60 s of the courtyard walk (scale 0.25, seed 0) from `gpm simulate`,
- ``handheld_10hz`` and ``handheld_2hz``: hand-held, the yaw swinging +-30 deg every 0.5 s, every sweep or 2 Hz;
- ``sim_gaps``: nothing recorded for 2, 4 and 8 s, 15, 30 and 45 s into the run;
- ``handheld_2hz_no_imu``, ``sim_gaps_no_imu``: the same without an IMU (a LiDAR-only recording).

Each is run by `gpm experiment` with one NDT thread in the global mode and both grid puzzle modes (the provider
nodelet in the localizer's manager, and the rospy provider); ``--modes`` runs only some. One JSON object per
variant and mode is printed and written to build/experiment_tracking/results.jsonl: the error of the published
poses over all played scans (and, on kitti00_far, over the straight parts), the scans with a pose and those more
than 1 m off, whether the localizer kept track (evaluation/tracking.py), the time to the first pose and its error
then, the localizer's per-scan time, and each mode's CPU and memory under both protocols with their ratio to the
global map's (resource_figures; medians of 3 runs for the as-recorded variants, one run otherwise). ``--cpu-hog``
keeps one core busy for the whole run (a busy loop pinned to core 1), for the same figures on a loaded 2-core
machine.
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import reference_check
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from shared_data import SHARED_REAL_DATA

from grid_puzzle_localization.evaluation.repeats import median_of
from grid_puzzle_localization.evaluation.resources import PROTOCOLS
from grid_puzzle_localization.evaluation.summary import BASELINE_MODE
from grid_puzzle_localization.evaluation.tracking import LOST_DEG, LOST_M, tracking
from grid_puzzle_localization.evaluation.trajectory import Trajectory, make_trajectory, read_tum
from grid_puzzle_localization.experiment.cpu_hog import CPU_HOG, start_cpu_hog, stop_cpu_hog
from grid_puzzle_localization.experiment.modes import DEFAULT_MODES
from grid_puzzle_localization.experiment.scenario import read_scenario
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array, xyz_records
from grid_puzzle_localization.recordings.poses import read_poses
from grid_puzzle_localization.recordings.scans import scan_files
from grid_puzzle_localization.util.atomic import atomic_write

ROOT = Path(__file__).resolve().parents[1]
KITTI = SHARED_REAL_DATA / "kitti00_far"
CAMPUS = SHARED_REAL_DATA / "nova_utd_tiles" / "tiles"  # a real campus map in 25 m tiles, 1.05 km x 0.86 km
CAMPUS_CELL_M = 5.0  # [m] occupancy cells that locate the campus's largest empty disc
CAMPUS_CLEARANCE_M = 50.0  # [m] the stretch's map and the campus's points stay at least this far apart
GPM = [sys.executable, str(ROOT / "scripts" / "gpm")]
MODES = DEFAULT_MODES  # global and both grid puzzle modes; block_map starts only from a pose, as two variants do not
KITTI_REFERENCE = "OXTS RTK GNSS/INS (KITTI ground truth)"
SIM_REFERENCE = "simulator ground truth"

# kitti00_far's stretches: 0-based lines of poses_kitti.txt and times.txt (stretches.txt), and a time [s] after
# the first played scan in the middle of each (60.5 and 69.3 s played) where the gap variant cuts 8 s.
STRETCHES = {"s1": (0, 251, 30.0), "s2": (252, 560, 35.0)}

# Sharp turns of kitti00_far (its README: keyframe numbers, i.e. scan file names). There the GNSS/INS poses and the
# registration of consecutive scans disagree by up to 0.58 m / 4.5 deg, about 0.4-0.5 m across a whole turn, so a
# tight error figure leaves them out, with TURN_MARGIN keyframes (about 6 m) on either side.
SHARP_TURNS = ((777, 791), (857, 863), (913, 926), (1105, 1110), (1224, 1231))
TURN_MARGIN = 3
# The reference itself is bent in the sharp turns (up to 1 m: its map is bent the same way), so no bound holds the
# localizer to it there; what it must keep is the map fit: at every scan within this distance of where the map holds
# that scan (map_fit), the `within_map_fit_bound` of a kitti00_far row.
MAP_FIT_BOUND_M = 0.10
REPEATS = 3  # runs of each mode of the as-recorded variants (medians of CPU and memory)


def straight(keyframes: np.ndarray, turns=SHARP_TURNS, margin: int = TURN_MARGIN) -> np.ndarray:
    """True for each keyframe number outside every sharp turn widened by ``margin`` keyframes on each side."""
    k = np.asarray(keyframes)[:, None]
    first, last = np.array(turns).T
    return ~np.any((k >= first - margin) & (k <= last + margin), axis=1)


@dataclass(frozen=True)
class Variant:
    scenario: str  # the directory the gpm command writes (variants that only start differently share it)
    command: tuple[str, ...]  # gpm command and arguments that write the scenario
    experiment: tuple[str, ...]  # extra arguments of gpm experiment
    reference: str
    campus: bool = False  # run on the scenario's map inside the campus map (campus_map())


def kitti_variants(name: str, first: int, last: int, gap_at: float) -> dict[str, Variant]:
    scans = (str(KITTI / "scans"), str(KITTI / "poses_kitti.txt"), "--times", str(KITTI / "times.txt"))
    base = ("import", *scans, "--first", str(first), "--last", str(last), "--map-every", "3")
    thinned = (*base, "--drop-fraction", "0.2", "--seed", "0", "--gap", f"{gap_at:g}", "8")
    urban = ("--preset", "urban")
    stem = f"kitti_{name}"
    return {
        # As recorded: each mode run REPEATS times, interleaved, for its CPU and memory (resource_figures).
        stem: Variant(stem, base, (*urban, "--repeats", str(REPEATS)), KITTI_REFERENCE),
        f"{stem}_drop20_gap8": Variant(f"{stem}_drop20_gap8", thinned, urban, KITTI_REFERENCE),
        f"{stem}_offset20_90": Variant(stem, base, (*urban, "--start-offset", "20", "90"), KITTI_REFERENCE),
        f"{stem}_hint20": Variant(stem, base, (*urban, "--start", "hint", "--hint-sigma", "20"), KITTI_REFERENCE),
        f"{stem}_none": Variant(stem, base, (*urban, "--start", "none"), KITTI_REFERENCE),
        f"{stem}_none_campus": Variant(stem, base, (*urban, "--start", "none"), KITTI_REFERENCE, campus=True),
    }


GAPS = ("--gap", "15", "2", "--gap", "30", "4", "--gap", "45", "8")
SIMULATE = ("simulate", "courtyard", "--scale", "0.25", "--duration", "60", "--seed", "0")
HARD = {
    "handheld_10hz": (*SIMULATE, "--yaw-swing"),
    "handheld_2hz": (*SIMULATE, "--yaw-swing", "--scan-rate", "2"),
    "handheld_2hz_no_imu": (*SIMULATE, "--yaw-swing", "--scan-rate", "2", "--no-imu"),
    "sim_gaps": (*SIMULATE, *GAPS),
    "sim_gaps_no_imu": (*SIMULATE, *GAPS, "--no-imu"),
}
VARIANTS: dict[str, Variant] = {
    **{v: k for name, (a, b, gap) in STRETCHES.items() for v, k in kitti_variants(name, a, b, gap).items()},
    **{name: Variant(name, command, (), SIM_REFERENCE) for name, command in HARD.items()},
}
SETS = {"real": [v for v in VARIANTS if v.startswith("kitti_")], "hard": list(HARD)}


def scan_stamps(bag: Path) -> np.ndarray:
    import rosbag  # only here: the pure functions above are tested without ROS

    with rosbag.Bag(str(bag)) as b:
        return np.array([m.header.stamp.to_sec() for _, m, _ in b.read_messages(topics=["points", "/points"])])


def kitti_indices(stamps: np.ndarray) -> np.ndarray:
    """Lines of times.txt and poses_kitti.txt (0-based, one a scan file) of the scans stamped ``stamps`` [s]."""
    times = np.loadtxt(KITTI / "times.txt")
    nearest = np.abs(stamps[:, None] - times[None, :]).argmin(axis=1)
    if np.any(np.abs(times[nearest] - stamps) > 1e-3):
        raise RuntimeError(f"a played scan's stamp is not in {KITTI / 'times.txt'}")
    return nearest


def kitti_keyframes(stamps: np.ndarray) -> np.ndarray:
    """Keyframe numbers (scan file names) of the scans stamped ``stamps`` [s]."""
    names = np.array([int(p.stem) for p in scan_files(KITTI / "scans")])
    return names[kitti_indices(stamps)]


@dataclass(frozen=True)
class MapFit:
    figures: dict  # the map fit's errors against the reference (row fields)
    poses: Trajectory  # where the map puts each played scan, at its stamp


def map_fit(map_path: Path, stamps: np.ndarray) -> MapFit:
    """Where the experiment's map itself puts each played scan: registered onto ``map_path`` from its reference pose
    (tools/reference_check.py's map check), how far it moves from that pose. A localizer that matches every scan
    exactly where the map fits it has these errors against the reference; where the reference is bent (the sharp
    turns), so is the map built from it."""
    files = scan_files(KITTI / "scans")
    poses, _ = read_poses(KITTI / "poses_kitti.txt", "kitti")
    rows = [reference_check.map_shift(map_path, files[k], poses[k]) for k in kitti_indices(stamps)]
    shifts = np.array([r["map_shift_m"] for r in rows])
    fitted = np.array([r["map_pose"] for r in rows])
    quat = Rotation.from_matrix(fitted[:, :3, :3]).as_quat()  # x y z w
    figures = {
        "map_fit_translation_rmse_m": rounded(np.sqrt(np.mean(shifts**2))),
        "map_fit_translation_max_m": rounded(shifts.max()),
        f"map_fit_scans_over_{LOST_M:g}m": int((shifts > LOST_M).sum()),
    }
    return MapFit(figures, make_trajectory(stamps, fitted[:, :3, 3], quat, "map fit"))


def campus_map(scenario_map: Path, out: Path) -> Path:
    """Writes ``out``: the map of a kitti00_far stretch inside the real campus map of CAMPUS (0.9 km^2, a loop road
    around an empty inside), which is moved so that the centre of its largest empty disc lies at the centre of the
    stretch's map. A start without a pose then searches a real map of the size it must handle, up to 1 km^2, where
    the stretch is a sixth of the area and the rest is real structure of another place. Raises RuntimeError when the
    two come closer than CAMPUS_CLEARANCE_M."""
    stretch = xyz_array(read_pcd(scenario_map).points)
    tiles = [xyz_array(read_pcd(f).points) for f in sorted(CAMPUS.glob("*.pcd"))]
    campus = np.concatenate([t for t in tiles if len(t)])
    low = campus[:, :2].min(axis=0)
    cells = np.floor((campus[:, :2] - low) / CAMPUS_CELL_M).astype(int)
    occupied = np.zeros(cells.max(axis=0) + 1, dtype=bool)
    occupied[cells[:, 0], cells[:, 1]] = True
    free = distance_transform_edt(~occupied)
    inside = low + (np.array(np.unravel_index(np.argmax(free), free.shape)) + 0.5) * CAMPUS_CELL_M
    shift = np.append(0.5 * (stretch[:, :2].min(axis=0) + stretch[:, :2].max(axis=0)) - inside, 0.0)
    campus += shift
    clearance = float(cKDTree(stretch[:, :2]).query(campus[:, :2])[0].min())
    if clearance < CAMPUS_CLEARANCE_M:
        raise RuntimeError(f"{scenario_map} reaches within {clearance:.1f} m of the campus map moved around it")
    write_pcd(out, xyz_records(np.concatenate([stretch, campus]).astype(np.float32)))
    return out


def path_length(reference: Trajectory, stamps: np.ndarray) -> float:
    """[m] driven between the first and the last played scan, along the reference."""
    if len(stamps) == 0:
        return 0.0
    xyz = reference.xyz[(reference.t >= stamps[0]) & (reference.t <= stamps[-1])]
    return float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())


def rounded(value: float | None, digits: int = 3) -> float | None:
    return None if value is None else round(float(value), digits)


def resource_figures(summary: dict, mode: str) -> dict:
    """The mode's CPU [% of one core] and RSS [MiB] under both protocols: the median over the runs (--repeats, run
    interleaved with the other modes) of each run's mean, and the median over the rounds of the run's ratio to the
    global map's run of the same round (None for the global map itself)."""
    resources = summary["modes"][mode]["resources"]
    spread = summary["repeats"]["spread"].get(mode, {})
    out: dict = {"repeats": summary["repeats"]["count"]}
    for protocol in PROTOCOLS:
        r, s = resources[protocol], spread.get(protocol, {})

        def vs_global(metric: str, s=s) -> float | None:
            ratios = s.get(metric, {}).get("vs_baseline", {}).get("per_repeat")
            return None if mode == BASELINE_MODE or not ratios else rounded(median_of(ratios))

        rss = r["rss_bytes"]["mean"]
        out[protocol] = {
            "cpu_percent": rounded(r["cpu_percent"]["mean"], 1),
            "rss_mib": None if rss is None else rounded(rss / 2**20, 1),
            "cpu_vs_global": vs_global("cpu_percent"),
            "rss_vs_global": vs_global("rss_bytes"),
        }
    return out


def figures(variant: str, scenario: Path, run: Path, modes: list[str], hog: str | None, fits: dict) -> list[dict]:
    """One row per mode. ``fits`` keeps map_fit() per scenario (the variants that only start differently share it);
    kitti00_far rows also give the localizer's error against the map fit (``to_map_fit_*``)."""
    summary = json.loads((run / "summary.json").read_text())
    inputs = read_scenario(scenario)
    reference = read_tum(inputs.ground_truth)
    stamps = scan_stamps(inputs.bag)
    kitti = variant.startswith("kitti_")
    kept = stamps[straight(kitti_keyframes(stamps))] if kitti else None
    if kitti and scenario not in fits:
        fits[scenario] = map_fit(inputs.global_map, stamps)
    start = summary.get("start") or {}
    rows = []
    for mode in modes:
        m = summary["modes"].get(mode) or {}
        trajectory = read_tum(run / mode / "trajectory.tum")
        track = tracking(reference, trajectory, stamps, summary["max_time_diff_s"])
        row = {
            "variant": variant,
            "mode": mode,
            "reference": VARIANTS[variant].reference,
            "start": start.get("mode"),
            "start_offset": [start.get("offset_m"), start.get("offset_deg")] if start.get("offset_m") else None,
            "hint_sigma_m": start.get("hint_sigma_m") if start.get("mode") == "hint" else None,
            "cpu_hog": hog,
            "scans_played": track.scans,
            "scans_with_pose": track.published,
            "translation_rmse_m": rounded(track.translation_rmse_m),
            "translation_max_m": rounded(track.translation_max_m),
            "rotation_max_deg": rounded(track.rotation_max_deg, 2),
            f"scans_over_{LOST_M:g}m": track.published_far,
            f"scans_within_{LOST_M:g}m_{LOST_DEG:g}deg": track.tracked,
            "longest_loss_s": round(track.longest_loss_s, 2),
            "recovery_after_gaps_s": [rounded(r, 2) for r in track.recovery_after_gaps_s],
        }
        if kept is not None:
            good = tracking(reference, trajectory, kept, summary["max_time_diff_s"])
            row.update(
                straight_scans_played=good.scans,
                straight_scans_with_pose=good.published,
                straight_translation_rmse_m=rounded(good.translation_rmse_m),
                straight_translation_max_m=rounded(good.translation_max_m),
                **fits[scenario].figures,
            )
            # The localizer against the map fit instead of the reference: how far it is from where the map holds
            # each scan (the reference's own bends left out).
            to_fit = tracking(fits[scenario].poses, trajectory, stamps, summary["max_time_diff_s"])
            row.update(
                to_map_fit_translation_rmse_m=rounded(to_fit.translation_rmse_m),
                to_map_fit_translation_max_m=rounded(to_fit.translation_max_m),
                within_map_fit_bound=to_fit.translation_max_m is not None
                and to_fit.translation_max_m <= MAP_FIT_BOUND_M,
            )
        first = m.get("start") or {}
        for key in ("first_pose", "first_accepted_pose"):
            pose = first.get(key)
            row[f"time_to_{key}_s"] = None if pose is None else rounded(pose["after_s"], 2)
            row[f"{key}_error_m"] = None if pose is None else rounded(pose["translation_error_m"])
            row[f"{key}_yaw_error_deg"] = None if pose is None else rounded(pose["yaw_error_deg"], 2)
        times = m.get("scan_time_ms") or {}
        row["scan_time_ms"] = {k: rounded(times.get(k), 1) for k in ("median", "p95", "p99", "max")}
        row["slow_scans"] = times.get("slow_scans")
        # What keeping the map current cost per metre driven: the map worker thread's CPU time over the drive.
        cpu_s, metres = times.get("map_worker_cpu_s"), path_length(reference, stamps)
        row["map_worker_cpu_ms_per_m"] = None if cpu_s is None or metres <= 0.0 else rounded(1e3 * cpu_s / metres, 2)
        row["resources"] = resource_figures(summary, mode)
        rows.append(row)
    return rows


def write_scenario(v: Variant, scenario: Path, stdout=None) -> None:
    """Writes the scenario directory of ``v`` (its gpm command) at ``scenario``; ``stdout`` as subprocess.run's."""
    subprocess.run([*GPM, *v.command, "-o", str(scenario), "--force", "--quiet"], check=True, stdout=stdout)


def run_variants(variants: list[str], modes: list[str], out: Path, rate: str, hog: str | None) -> int:
    out.mkdir(parents=True, exist_ok=True)
    results, written, failed, fits = [], set(), 0, {}
    for variant in variants:
        v = VARIANTS[variant]
        scenario, run = out / v.scenario, out / f"{variant}_run"
        if v.scenario not in written:
            write_scenario(v, scenario)
            written.add(v.scenario)
        shutil.rmtree(run, ignore_errors=True)  # its tiles were cut from a map that may have been replaced
        experiment = [*GPM, "experiment", str(scenario), "-o", str(run), "--ndt-threads", "1", "--rate", rate]
        experiment += ["--modes", *modes, "--empty-map-seconds", "0", *v.experiment]
        if v.campus:
            experiment += ["--map", str(campus_map(scenario / "global_map.pcd", out / f"{v.scenario}_campus_map.pcd"))]
        log = out / f"{variant}_experiment.log"
        with open(log, "w") as f:
            done = subprocess.run(experiment, stdout=f, stderr=subprocess.STDOUT)
        if done.returncode != 0:
            failed += 1
            rows = [{"variant": variant, "cpu_hog": hog, "error": f"gpm experiment failed, see {log}"}]
        else:
            rows = figures(variant, scenario, run, modes, hog, fits)
        for row in rows:
            print(json.dumps(row), flush=True)
        results += rows
        with atomic_write(out / "results.jsonl") as f:
            f.writelines(json.dumps(row) + "\n" for row in results)
    return 1 if failed else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", nargs="+", help=f"sets ({', '.join(SETS)}) or variants ({', '.join(VARIANTS)})")
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "experiment_tracking")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES), help="modes to run (default all)")
    parser.add_argument("--rate", default="1", help="bag playback speed (default 1)")
    parser.add_argument(
        "--cpu-hog", action="store_true", help="keep core 1 busy for the whole run: " + shlex.join(CPU_HOG)
    )
    args = parser.parse_args()
    variants = [v for name in args.variants for v in SETS.get(name, [name])]
    for variant in variants:
        if variant not in VARIANTS:
            parser.error(f"unknown variant {variant} (use {', '.join(SETS)} or {', '.join(VARIANTS)})")
    if any(v.startswith("kitti_") for v in variants) and not (KITTI / "scans").is_dir():
        print(
            f"experiment-real: the kitti00_far keyframes are not at {KITTI} (no scans/ there); this experiment needs "
            "the team's real data (../shared/data/real beside the clone, or GPL_SHARED_DATA)",
            file=sys.stderr,
        )
        return 2
    if any(VARIANTS[v].campus for v in variants) and not CAMPUS.is_dir():
        print(
            f"experiment-real: the campus map tiles are not at {CAMPUS} (the team's real data, nova_utd_tiles); "
            "the *_none_campus variants need them",
            file=sys.stderr,
        )
        return 2
    try:
        hog = start_cpu_hog() if args.cpu_hog else None
    except RuntimeError as e:
        parser.error(f"--cpu-hog: {e}")
    try:
        return run_variants(variants, args.modes, args.out, args.rate, shlex.join(CPU_HOG) if hog else None)
    finally:
        if hog is not None:
            stop_cpu_hog(hog)


if __name__ == "__main__":
    sys.exit(main())
