#!/usr/bin/env python3
"""make experiment-real: the MulRan Riverside02 keyframes (real Ouster OS1-64 scans from a car at about 10 m/s,
../shared/data/real/mulran_riverside02) imported with `gpm import` and localized by `gpm experiment` in both modes:

- ``plain``: scans 50-215, the map from every 3rd scan, the others played;
- ``drop10``: the same with 10 % of the played scans dropped at random;
- ``gaps``: the same with gaps of 2, 4 and 8 s cut into the bag, 15, 30 and 45 s after the first scan.

The reference poses are the FAST-LIO2 odometry (odom_poses.txt): SLAM output, locally consistent to about
0.1 m over these scans, not ground truth. The recording itself pauses for 4.3 s and 8.5 s about 65 s in (the
car stopped, so no keyframe was saved). Prints one JSON object per run and mode: the APE of the published
poses and whether the localizer kept track (evaluation/tracking.py). Outputs go to build/experiment_real/.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import rosbag

from grid_puzzle_localization.evaluation.tracking import LOST_M, tracking
from grid_puzzle_localization.evaluation.trajectory import read_tum

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("GPL_SHARED_DATA") or ROOT.parent / "shared" / "data" / "real")
MULRAN = SHARED / "mulran_riverside02"
GPM = [sys.executable, str(ROOT / "scripts" / "gpm")]
BASE = ["--first", "50", "--last", "215", "--map-every", "3"]
VARIANTS = {
    "plain": [],
    "drop10": ["--drop-fraction", "0.1", "--seed", "0"],
    "gaps": ["--gap", "15", "2", "--gap", "30", "4", "--gap", "45", "8"],
}
MODES = ("global", "grid_puzzle")


def scan_stamps(bag: Path) -> list[float]:
    with rosbag.Bag(str(bag)) as b:
        return [m.header.stamp.to_sec() for _, m, _ in b.read_messages(topics=["points"])]


def figures(variant: str, scenario: Path, run: Path) -> list[dict]:
    summary = json.loads((run / "summary.json").read_text())
    reference = read_tum(scenario / "ground_truth.tum")
    stamps = scan_stamps(scenario / "recording.bag")
    rows = []
    for mode in MODES:
        ape = (summary["modes"].get(mode) or {}).get("ape") or {}
        track = tracking(reference, read_tum(run / mode / "trajectory.tum"), stamps, summary["max_time_diff_s"])
        rows.append(
            {
                "data": "mulran_riverside02 scans 50-215, reference: FAST-LIO2 odometry",
                "variant": variant,
                "mode": mode,
                "ape_translation_rmse_m": (ape.get("translation_m") or {}).get("rmse"),
                "ape_rotation_rmse_deg": (ape.get("rotation_deg") or {}).get("rmse"),
                "scans_played": track.scans,
                "scans_with_pose": track.published,
                f"scans_within_{LOST_M:g}m": track.tracked,
                "translation_max_m": track.translation_max_m,
                "longest_loss_s": round(track.longest_loss_s, 2),
                "recovery_after_gaps_s": [None if r is None else round(r, 2) for r in track.recovery_after_gaps_s],
            }
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", nargs="*", default=list(VARIANTS), help=f"of {', '.join(VARIANTS)} (default all)")
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "experiment_real")
    parser.add_argument("--rate", default="1", help="bag playback speed (default 1)")
    args = parser.parse_args()
    if not (MULRAN / "Scans").is_dir():
        print(
            f"experiment-real: the MulRan keyframes are not at {MULRAN}; this experiment needs the team's real data"
            " (../shared/data/real beside the clone, or GPL_SHARED_DATA)",
            file=sys.stderr,
        )
        return 2
    for variant in args.variants:
        if variant not in VARIANTS:
            parser.error(f"unknown variant {variant} (use {', '.join(VARIANTS)})")
        scenario, run = args.out / f"mulran_{variant}", args.out / f"mulran_{variant}_run"
        imports = [str(MULRAN / "Scans"), str(MULRAN / "odom_poses.txt"), "--times", str(MULRAN / "times.txt")]
        subprocess.run(
            [*GPM, "import", *imports, *BASE, *VARIANTS[variant], "-o", str(scenario), "--force", "--quiet"], check=True
        )
        done = subprocess.run(
            [*GPM, "experiment", str(scenario), "-o", str(run), "--ndt-threads", "1", "--rate", args.rate],
            stdout=subprocess.DEVNULL,
        )
        if done.returncode != 0:
            print(json.dumps({"variant": variant, "error": f"gpm experiment failed ({done.returncode})"}), flush=True)
            continue
        for row in figures(variant, scenario, run):
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
