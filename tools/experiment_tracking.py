#!/usr/bin/env python3
"""Tracking on the recordings that broke the localizer: `make experiment-real` and `make experiment-hard`.

Real (``make experiment-real``): the MulRan Riverside02 keyframes (real Ouster OS1-64 scans from a car at about
10 m/s, ../shared/data/real/mulran_riverside02, or $GPL_SHARED_DATA) imported with `gpm import`: scans 50-215,
the map from every 3rd scan, the others played.
- ``mulran``: as recorded;
- ``mulran_drop10``: 10 % of the played scans dropped at random;
- ``mulran_gaps``: gaps of 2, 4 and 8 s cut 15, 30 and 45 s after the first scan.
Grid puzzle mode uses the urban preset's window (n 25, k 20, s 2 m) here: the demo window ends 17 m from the car.
The reference poses are the FAST-LIO2 odometry (odom_poses.txt): SLAM output, not ground truth. Where
registering consecutive scans disagrees with it (tools/reference_check.py: scans 63-99, 103-122, 152-161 and
167-171) it is metres off, and so is the map built from it there; the figures are also given over the scans whose
reference agrees with the scans on both sides (``trusted``). The recording itself pauses for 4.3 s and 8.5 s about
65 s in (the car stopped, so no keyframe was saved).

Simulated (``make experiment-hard``): 60 s of the courtyard walk (scale 0.25, seed 0) from `gpm simulate`,
- ``handheld_10hz`` and ``handheld_2hz``: hand-held, the yaw swinging +-30 deg every 0.5 s, every sweep or 2 Hz;
- ``sim_gaps``: nothing recorded for 2, 4 and 8 s, 15, 30 and 45 s into the run;
- ``handheld_2hz_no_imu``, ``sim_gaps_no_imu``: the same without an IMU (a LiDAR-only recording, like the
  real hand-held one that lost track).

Each is run by `gpm experiment` in both modes; one JSON object per variant and mode is printed: the APE of the
published poses and whether the localizer kept track (evaluation/tracking.py). Outputs go to
build/experiment_tracking/.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import rosbag
from reference_check import cached_check
from shared_data import SHARED_REAL_DATA

from grid_puzzle_localization.evaluation.tracking import LOST_DEG, LOST_M, tracking
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.scenario import read_scenario

ROOT = Path(__file__).resolve().parents[1]
MULRAN = SHARED_REAL_DATA / "mulran_riverside02"
GPM = [sys.executable, str(ROOT / "scripts" / "gpm")]
MODES = ("global", "grid_puzzle")
GAPS = ["--gap", "15", "2", "--gap", "30", "4", "--gap", "45", "8"]
MULRAN_FIRST, MULRAN_LAST = 50, 215
MULRAN_IMPORT = [
    *(str(MULRAN / "Scans"), str(MULRAN / "odom_poses.txt"), "--times", str(MULRAN / "times.txt")),
    *("--first", str(MULRAN_FIRST), "--last", str(MULRAN_LAST), "--map-every", "3"),
]
SIMULATE = ["courtyard", "--scale", "0.25", "--duration", "60", "--seed", "0"]
# variant -> (gpm command and its arguments, what the reference poses are)
VARIANTS: dict[str, tuple[list[str], str]] = {
    "mulran": (["import", *MULRAN_IMPORT], "FAST-LIO2 odometry"),
    "mulran_drop10": (["import", *MULRAN_IMPORT, "--drop-fraction", "0.1", "--seed", "0"], "FAST-LIO2 odometry"),
    "mulran_gaps": (["import", *MULRAN_IMPORT, *GAPS], "FAST-LIO2 odometry"),
    "handheld_10hz": (["simulate", *SIMULATE, "--yaw-swing"], "simulator ground truth"),
    "handheld_2hz": (["simulate", *SIMULATE, "--yaw-swing", "--scan-rate", "2"], "simulator ground truth"),
    "handheld_2hz_no_imu": (
        ["simulate", *SIMULATE, "--yaw-swing", "--scan-rate", "2", "--no-imu"],
        "simulator ground truth",
    ),
    "sim_gaps": (["simulate", *SIMULATE, *GAPS], "simulator ground truth"),
    "sim_gaps_no_imu": (["simulate", *SIMULATE, *GAPS, "--no-imu"], "simulator ground truth"),
}
SETS = {
    "real": ["mulran", "mulran_drop10", "mulran_gaps"],
    "hard": ["handheld_10hz", "handheld_2hz", "handheld_2hz_no_imu", "sim_gaps", "sim_gaps_no_imu"],
}


def scan_stamps(bag: Path) -> list[float]:
    with rosbag.Bag(str(bag)) as b:
        return [m.header.stamp.to_sec() for _, m, _ in b.read_messages(topics=["points"])]


def trusted_stamps() -> np.ndarray:
    """Times [s] of the MulRan scans whose reference agrees with registration on both sides."""
    _, trusted = cached_check(
        MULRAN / "Scans", MULRAN / "odom_poses.txt", MULRAN_FIRST, MULRAN_LAST, ROOT / "build" / "reference_check"
    )
    return np.loadtxt(MULRAN / "times.txt")[sorted(trusted)]


def figures(variant: str, scenario: Path, run: Path, trusted: np.ndarray | None) -> list[dict]:
    """One row per mode; with ``trusted`` (stamps of the scans whose reference is trusted) the figures over them too."""
    summary = json.loads((run / "summary.json").read_text())
    inputs = read_scenario(scenario)
    reference = read_tum(inputs.ground_truth)
    stamps = scan_stamps(inputs.bag)
    rows = []
    for mode in MODES:
        ape = (summary["modes"].get(mode) or {}).get("ape") or {}
        trajectory = read_tum(run / mode / "trajectory.tum")
        track = tracking(reference, trajectory, stamps, summary["max_time_diff_s"])
        extra = {}
        if trusted is not None:
            played = np.asarray(stamps)
            kept = played[np.min(np.abs(played[:, None] - trusted[None, :]), axis=1) < 1e-3]
            good = tracking(reference, trajectory, kept, summary["max_time_diff_s"])
            extra = {
                "trusted_scans_played": good.scans,
                "trusted_scans_with_pose": good.published,
                f"trusted_scans_within_{LOST_M:g}m_{LOST_DEG:g}deg": good.tracked,
                "trusted_translation_rmse_m": good.translation_rmse_m,
                "trusted_translation_max_m": good.translation_max_m,
            }
        rows.append(
            {
                "variant": variant,
                "mode": mode,
                "reference": VARIANTS[variant][1],
                "ape_translation_rmse_m": (ape.get("translation_m") or {}).get("rmse"),
                "ape_rotation_rmse_deg": (ape.get("rotation_deg") or {}).get("rmse"),
                "scans_played": track.scans,
                "scans_with_pose": track.published,
                f"scans_within_{LOST_M:g}m_{LOST_DEG:g}deg": track.tracked,
                "translation_max_m": track.translation_max_m,
                "rotation_max_deg": track.rotation_max_deg,
                "longest_loss_s": round(track.longest_loss_s, 2),
                "recovery_after_gaps_s": [None if r is None else round(r, 2) for r in track.recovery_after_gaps_s],
                **extra,
            }
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", nargs="+", help=f"sets ({', '.join(SETS)}) or variants ({', '.join(VARIANTS)})")
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "experiment_tracking")
    parser.add_argument("--rate", default="1", help="bag playback speed (default 1)")
    args = parser.parse_args()
    variants = [v for name in args.variants for v in SETS.get(name, [name])]
    for variant in variants:
        if variant not in VARIANTS:
            parser.error(f"unknown variant {variant} (use {', '.join(SETS)} or {', '.join(VARIANTS)})")
    if any(v.startswith("mulran") for v in variants) and not (MULRAN / "Scans").is_dir():
        print(
            f"experiment-real: the MulRan keyframes are not at {MULRAN}; this experiment needs the team's real data"
            " (../shared/data/real beside the clone, or GPL_SHARED_DATA)",
            file=sys.stderr,
        )
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for variant in variants:
        scenario, run = args.out / variant, args.out / f"{variant}_run"
        command = VARIANTS[variant][0]
        subprocess.run([*GPM, *command, "-o", str(scenario), "--force", "--quiet"], check=True)
        shutil.rmtree(run, ignore_errors=True)  # its tiles were cut from the map just replaced
        experiment = [*GPM, "experiment", str(scenario), "-o", str(run), "--ndt-threads", "1", "--rate", args.rate]
        experiment += ["--modes", *MODES]
        if variant.startswith("mulran"):
            # A car's 64-beam scans reach far beyond the demo window (n 8: 17 m each side); the urban preset's
            # window (n 25: 51 m) covers the range the scans are matched over.
            experiment += ["--preset", "urban"]
        log = args.out / f"{variant}_experiment.log"
        with open(log, "w") as f:
            done = subprocess.run(experiment, stdout=f, stderr=subprocess.STDOUT)
        if done.returncode != 0:
            print(json.dumps({"variant": variant, "error": f"gpm experiment failed, see {log}"}), flush=True)
            continue
        trusted = trusted_stamps() if variant.startswith("mulran") else None
        for row in figures(variant, scenario, run, trusted):
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
