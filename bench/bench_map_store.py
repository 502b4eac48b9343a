"""`make bench-map-store`: the map store against a real nginx on localhost (docs/map_store.md#benchmark).

1. Fetch throughput without any delay: bench_map_store (C++) fetches a window of tiles cold, warm and polls the
   index; its JSON lines are passed through.
2. A drive through the core localizer with its tiles fetched over HTTP: the first URBAN_SECONDS of the paper's urban
   route (`gpm simulate urban`, HDL-32E at 10 Hz), its prior map cut by `gpm tile` into the urban preset's 2 m tiles
   and a (2n+1)^2 window of them (n = 25) following the pose; nginx serves them behind a delaying proxy
   (bench/delay_proxy.py: 25 ms each way, so a 50 ms round trip, and 10 MB/s). bench_localizer runs it in real
   time, in tiles mode with the tiles named by reference, as the provider sends them:
   - `disk`: from the tile directory (the reference run);
   - `store_cold`: from the URL with an empty disk cache;
   - `store_warm`: again, on the cache the cold run left;
   - `store_outage`: an empty cache, nginx stopped a third into the drive for OUTAGE_LENGTH_S and started again;
   and `repeat`, bench-localizer's control (the same scan at every slot: the machine's own latency spread).
   Each run prints bench_localizer's JSON line plus: the between-runs RMSE of its poses against the disk run's,
   bytes fetched per km driven, and for the outage the scans matched while the server was down and the time from
   its return until the store answered again.
3. A cold start and a drive on throttled stores (bench_map_store_throttled.py): both stretches of kitti00_far, 2 m
   tiles, from disk, from nginx behind the proxy limited to 50, 100 and 200 tiles/s with a 100 ms round trip, and
   from `python3 -m http.server`, then cut into 4 m tiles from disk and at 50 and 100 tiles/s; one JSON line per run
   with the figures and targets of issue 58.
--quick: bench-localizer's synthetic street instead, 6 s with a 1.5 s outage, and part 3 on it at one rate (checks
that it runs).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import bench_localizer
import bench_map_store_throttled
import numpy as np
import replay_scenario
from delay_proxy import DelayProxy
from fixtures import nginx_server
from fixtures import synthetic_scene as ss
from hardware import cpu_model

from grid_puzzle_localization.pcd import write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.provider.window import PRESETS
from grid_puzzle_localization.tiling import TileConfig, tile_map

ROOT = Path(__file__).resolve().parents[1]
ONE_WAY_DELAY_S = 0.025
RATE_BYTES_S = 10e6
URBAN_SECONDS = 180.0  # [s] of the urban route driven (about 0.8 km)
URBAN_TILE_SIZE = 2.0  # [m] the paper's s
OUTAGE_LENGTH_S = 10.0
QUICK_SECONDS, QUICK_OUTAGE_S = 6.0, 1.5


@dataclass(frozen=True)
class Drive:
    """A drive for bench_localizer: its input file, and the directory nginx serves (the tiles at map/)."""

    route: str  # "urban" or "street" (--quick): in every JSON line of the drive
    data: Path
    www: Path
    seconds: float
    tile_size: float  # [m]
    half_window: int  # n: the window is (2n+1)^2 tiles around the pose


def cut_tiles(map_pcd: Path, tile_size: float) -> Path:
    """The tiles of ``map_pcd`` as `gpm tile` writes them, at www/map beside it; returns www (what nginx serves)."""
    www = map_pcd.parent / "www"
    www.mkdir()
    tile_map([map_pcd], www / "map", TileConfig(grid_size=tile_size, progress=False))
    return www


def urban_drive(tmp: Path) -> Drive:
    """The first URBAN_SECONDS of the urban route, simulated afresh (deterministic by seed)."""
    scenario = tmp / "urban"
    gpm = [sys.executable, str(ROOT / "scripts/gpm")]
    subprocess.run(
        [*gpm, "simulate", "urban", "--duration", str(URBAN_SECONDS), "-o", str(scenario), "--quiet"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    data = tmp / "drive.bin"
    replay_scenario.write_input(scenario, data)
    www = cut_tiles(scenario / "global_map.pcd", URBAN_TILE_SIZE)
    return Drive("urban", data, www, URBAN_SECONDS, URBAN_TILE_SIZE, PRESETS["urban"][0])


def street_drive(tmp: Path) -> Drive:
    """bench-localizer's synthetic street, QUICK_SECONDS long, in its 7 x 7 window of 10 m tiles."""
    drive = ss.Drive(duration=QUICK_SECONDS)
    data = tmp / "drive.bin"
    bench_localizer.write_input(data, drive, imu_rate=100.0, seed=1)
    street = ss.sample_map(ss.make_scene(length=drive.x0 + drive.speed * drive.duration + 40.0)).astype(np.float32)
    records = np.zeros(len(street), dtype=XYZ_DTYPE)
    for axis, name in enumerate("xyz"):
        records[name] = street[:, axis]
    (tmp / "street").mkdir()
    write_pcd(tmp / "street/map.pcd", records)
    return Drive("street", data, cut_tiles(tmp / "street/map.pcd", 10.0), QUICK_SECONDS, 10.0, 3)


def read_trace(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    columns = ("x", "y", "accepted", "monotonic_s", "map_store_reachable")
    return {name: np.array([float(r[name]) for r in rows]) for name in columns}


def between_runs_rmse(trace: dict, reference: dict) -> float:
    d = np.hypot(trace["x"] - reference["x"], trace["y"] - reference["y"])
    return float(np.sqrt(np.mean(d * d)))


def outage_figures(trace: dict, down_at: float, up_at: float) -> dict:
    during = (trace["monotonic_s"] >= down_at) & (trace["monotonic_s"] < up_at)
    after = trace["monotonic_s"] >= up_at
    back = trace["monotonic_s"][after & (trace["map_store_reachable"] > 0)]
    return {
        "outage_s": round(up_at - down_at, 2),
        "scans_during_outage": int(during.sum()),
        "matched_during_outage": int(trace["accepted"][during].sum()),
        "store_answered_after_return_s": round(float(back[0] - up_at), 2) if back.size else None,
        "matched_after_return": int(trace["accepted"][after].sum()),
        "scans_after_return": int(after.sum()),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the synthetic street, 6 s, with a 1.5 s outage")
    parser.add_argument("--traces", type=Path, help="keep the per-scan traces of the throttled runs (part 3) in DIR")
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh (the Makefile sources it)
    bin_dir = workspace / "devel/lib/grid_puzzle_localization"
    args = parser.parse_args()
    if nginx_server.binary() is None:
        raise SystemExit("bench-map-store needs nginx (apt-get install nginx-light; `make setup` installs it)")
    hardware = {"cpu_model": cpu_model(), "cores": os.cpu_count(), "load_average_1min": os.getloadavg()[0]}

    throughput = subprocess.run(
        [str(bin_dir / "bench_map_store"), *(["--quick"] if args.quick else [])],
        check=True,
        capture_output=True,
        text=True,
    )
    print(throughput.stdout, end="", flush=True)

    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        drive = street_drive(tmp) if args.quick else urban_drive(tmp)
        outage_length = QUICK_OUTAGE_S if args.quick else OUTAGE_LENGTH_S
        outage_at = drive.seconds / 3
        server = nginx_server.NginxServer(drive.www)
        server.start()
        proxy = DelayProxy(server.port, ONE_WAY_DELAY_S, RATE_BYTES_S)
        proxy.start()
        url = f"http://127.0.0.1:{proxy.port}/map"
        # as the provider names the index it serves (docs/map_store.md)
        revision = "sha256:" + hashlib.sha256((drive.www / "map/index.json").read_bytes()).hexdigest()[:16]
        link = {"one_way_delay_ms": ONE_WAY_DELAY_S * 1e3, "rate_mb_s": RATE_BYTES_S / 1e6}
        try:

            def run(name: str, source: str | None, cache: Path | None = None) -> tuple[dict, dict | None]:
                mode = "repeat" if source is None else "tiles"
                trace = tmp / f"{name}.csv"
                cmd = [str(bin_dir / "bench_localizer"), str(drive.data), mode, "--tile-size", str(drive.tile_size)]
                cmd += ["--window", str(drive.half_window)]
                if source is not None:
                    cmd += ["--tile-source", source, "--index-revision", revision, "--trace", str(trace)]
                if cache is not None:
                    cmd += ["--map-store-cache", str(cache)]
                done = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True)  # its stderr is ours
                out = done.stdout
                return {"run": name, **json.loads(out)}, (read_trace(trace) if source is not None else None)

            def report(row: dict, trace: dict | None, reference: dict | None, **extra) -> None:
                if trace is not None and reference is not None:
                    row["between_runs_rmse_m"] = round(between_runs_rmse(trace, reference), 5)
                if row["run"].startswith("store"):
                    row["bytes_fetched_per_km"] = round(row["map_store"]["bytes_fetched"] / (row["distance_m"] / 1e3))
                print(json.dumps({**row, "route": drive.route, **extra, **hardware}), flush=True)

            control, _ = run("repeat", None)
            report(control, None, None)
            disk_row, disk = run("disk", str(drive.www / "map"))
            report(disk_row, disk, disk)
            cold_row, cold = run("store_cold", url, tmp / "cache")
            report(cold_row, cold, disk, link=link)
            warm_row, warm = run("store_warm", url, tmp / "cache")
            report(warm_row, warm, disk, link=link)

            window: list[float] = []

            def interrupt() -> None:
                time.sleep(outage_at)
                server.stop()
                window.append(time.monotonic())
                time.sleep(outage_length)
                server.start()
                window.append(time.monotonic())

            timer = threading.Thread(target=interrupt, daemon=True)
            timer.start()
            outage_row, outage = run("store_outage", url, tmp / "cache_outage")
            timer.join()
            report(outage_row, outage, disk, link=link, **outage_figures(outage, window[0], window[1]))
        finally:
            proxy.stop()
            server.close()
        street = None
        if args.quick:
            street = bench_map_store_throttled.Stretch(
                drive.route, drive.data, drive.www / "map", drive.tile_size, drive.half_window
            )
        bench_map_store_throttled.run(bin_dir, args.quick, street, args.traces)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
