"""`make bench-map-store`: the map store against a real nginx on localhost (docs/map_store.md#benchmark).

1. Fetch throughput without any delay: bench_map_store (C++) fetches a window of tiles cold, warm and polls the
   index; its JSON lines are passed through.
2. A drive through the core localizer with its tiles fetched over HTTP: bench-localizer's synthetic drive (a 60 s
   street at 5 m/s, 10 Hz scans, a 7 x 7 window of 10 m tiles following the pose), the map cut by `gpm tile`,
   nginx behind a delaying proxy (bench/delay_proxy.py: 25 ms each way, so a 50 ms round trip, and 10 MB/s).
   bench_localizer runs it in real time, in tiles mode with the tiles named by reference, as the provider sends
   them:
   - `disk`: from the tile directory (the reference run);
   - `store_cold`: from the URL with an empty disk cache;
   - `store_warm`: again, on the cache the cold run left;
   - `store_outage`: an empty cache, nginx stopped OUTAGE_S into the drive for OUTAGE_LENGTH_S and started again;
   and `repeat`, bench-localizer's control (the same scan at every slot: the machine's own latency spread).
   Each run prints bench_localizer's JSON line plus: the between-runs RMSE of its poses against the disk run's,
   bytes fetched per km driven, and for the outage the scans matched while the server was down and the time from
   its return until the store answered again.
--quick: a 10 s drive with a 2 s outage (checks that it runs).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from bench_localizer import write_input
from delay_proxy import DelayProxy
from fixtures import nginx_server
from fixtures import synthetic_scene as ss
from hardware import cpu_model

from grid_puzzle_localization.pcd import write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.tiling import TileConfig, tile_map

TILE_SIZE = 10.0  # [m] as bench-localizer
ONE_WAY_DELAY_S = 0.025
RATE_BYTES_S = 10e6


def write_tiles(drive_map: np.ndarray, directory: Path) -> None:
    records = np.zeros(len(drive_map), dtype=XYZ_DTYPE)
    for axis, name in enumerate("xyz"):
        records[name] = drive_map[:, axis]
    write_pcd(directory / "map.pcd", records)
    (directory / "www").mkdir()
    tile_map([directory / "map.pcd"], directory / "www" / "map", TileConfig(grid_size=TILE_SIZE, progress=False))


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
    parser.add_argument("--quick", action="store_true", help="a 10 s drive with a 2 s outage")
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh (the Makefile sources it)
    bin_dir = workspace / "devel/lib/grid_puzzle_localization"
    args = parser.parse_args()
    if nginx_server.binary() is None:
        raise SystemExit("bench-map-store needs nginx (apt-get install nginx-light; `make setup` installs it)")
    duration, outage_at, outage_length = (10.0, 3.0, 2.0) if args.quick else (60.0, 20.0, 10.0)
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
        data = tmp / "drive.bin"
        drive = ss.Drive(duration=duration)
        write_input(data, drive, imu_rate=100.0, seed=1)
        scene = ss.make_scene(length=drive.x0 + drive.speed * drive.duration + 40.0)
        write_tiles(ss.sample_map(scene).astype(np.float32), tmp)
        server = nginx_server.NginxServer(tmp / "www")
        server.start()
        proxy = DelayProxy(server.port, ONE_WAY_DELAY_S, RATE_BYTES_S)
        proxy.start()
        url = f"http://127.0.0.1:{proxy.port}/map"
        # as the provider names the index it serves (docs/map_store.md)
        revision = "sha256:" + hashlib.sha256((tmp / "www/map/index.json").read_bytes()).hexdigest()[:16]
        link = {"one_way_delay_ms": ONE_WAY_DELAY_S * 1e3, "rate_mb_s": RATE_BYTES_S / 1e6}
        try:

            def run(name: str, source: str | None, cache: Path | None = None) -> tuple[dict, dict | None]:
                mode = "repeat" if source is None else "tiles"
                trace = tmp / f"{name}.csv"
                cmd = [str(bin_dir / "bench_localizer"), str(data), mode, "--tile-size", str(TILE_SIZE)]
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
                print(json.dumps({**row, **extra, **hardware}), flush=True)

            control, _ = run("repeat", None)
            report(control, None, None)
            disk_row, disk = run("disk", str(tmp / "www" / "map"))
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
