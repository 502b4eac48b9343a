"""`make bench-map-store`, part 3: a start and a drive through the localizer on throttled map stores.

Each stretch of kitti00_far (real Velodyne HDL-64E keyframes with their OXTS RTK GNSS/INS poses, imported as
`make experiment-real` imports them: tools/experiment_tracking.py, the map from every 3rd scan, the others played at
their own stamps) is cut into the urban preset's 2 m tiles, and bench_localizer drives it in real time in tiles mode,
the tiles named by reference in a window of 51 x 51 tiles (the preset's n = 25) following the pose, from a cold
start: the first window is handed to the map worker with the first scan, not waited for. The stores:
- `disk`: the tile directory (the reference run);
- `nginx_throttled` at 50, 100 and 200 tiles/s: nginx behind bench/delay_proxy.py, which holds every chunk 50 ms
  each way (a request costs a 100 ms round trip) and passes at most that many requests a second on to nginx, all
  connections together; an empty disk cache each run;
- `python_http_server`: `python3 -m http.server` serving the tile directory, no proxy (HTTP/1.0, a connection per
  tile); an empty disk cache.
Then the same stretch cut into CAR_TILE_SIZE = 4 m tiles (a window of the same extent, n = 12) from disk and at the
rates of CAR_TILE_RATES: a square of map_wait_half_side about a car at v takes in v 2 h / s^2 tiles a second (90 at
9 m/s with 2 m tiles, 22 with 4 m ones), so 2 m tiles outrun a store of 50 or 100 tiles/s and 4 m tiles do not.
One run each (repeats: 1). Each prints one JSON line with what the issue's targets ask for (`targets`):
- the first pose is published once the tiles under its scan (those meeting the square of map_wait_half_side = 20 m
  each side of its true position: 40 m) have arrived (`published_with_tiles_missing` counts the published scans of
  the whole run whose square had tiles in flight), and no published pose is more than 1 m off the reference;
- the first pose comes within first_pose_bound_s = (the non-empty tiles of that square, counted in index.json) /
  (fetch rate) + 2 s of the first scan; the fetch rate is the throttle's, or for disk and python_http_server the
  rate measured in the run (the first window's tiles / the time until all of them were in the map);
- from that first pose on, the share of scans with a pose and the RMSE of their error against the reference are
  within 1 % and 1 cm of the disk run's over the same scans;
- no scan is lost where the disk run's same scan is not while tiles of the window were in flight.
--quick: bench-localizer's synthetic street (the drive part 2 of bench_map_store.py drives), the disk run and one
rate. Without ../shared (tools/shared_data.py), one line says that the kitti00_far runs were skipped.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import replay_scenario
from delay_proxy import DelayProxy
from fixtures import nginx_server
from fixtures.python_http_server import python_http_server
from hardware import cpu_model

from grid_puzzle_localization.provider.window import PRESETS
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiling import TileConfig, tile_map

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from experiment_tracking import KITTI, STRETCHES, VARIANTS, rounded, write_scenario  # noqa: E402

TILE_SIZE = 2.0  # [m] the urban preset's s
RATES = (50.0, 100.0, 200.0)  # [tiles/s]
CAR_TILE_SIZE = 4.0  # [m] tiles a car's square of map_wait_half_side does not outrun at CAR_TILE_RATES
CAR_TILE_RATES = (50.0, 100.0)  # [tiles/s]
QUICK_RATE = 100.0
ONE_WAY_DELAY_S = 0.05  # each way: a request's round trip is 100 ms
START_HALF_SIDE = 20.0  # [m] LocalizerConfig::map_wait_half_side (default): the start square is 40 m
BOUND_SLACK_S = 2.0
MAX_ERROR_M = 1.0
SHARE_TOLERANCE = 0.01
RMSE_TOLERANCE_M = 0.01
BENCH = "map_store_throttled"


@dataclass(frozen=True)
class Stretch:
    name: str
    data: Path  # bench_localizer's input
    tiles: Path  # the tile directory (index.json and the tiles)
    tile_size: float
    half_window: int


def kitti_stretch(name: str, tmp: Path) -> Stretch:
    """Stretch ``name`` (s1, s2) of kitti00_far, imported as `make experiment-real` does, tiled at TILE_SIZE."""
    scenario = tmp / f"kitti_{name}"
    write_scenario(VARIANTS[f"kitti_{name}"], scenario, stdout=subprocess.DEVNULL)
    data = tmp / f"kitti_{name}.bin"
    replay_scenario.write_input(scenario, data)
    www = tmp / f"kitti_{name}_www"
    www.mkdir()
    tile_map([scenario / "global_map.pcd"], www / "map", TileConfig(grid_size=TILE_SIZE, progress=False))
    return Stretch(f"kitti00_far_{name}", data, www / "map", TILE_SIZE, PRESETS["urban"][0])


def retiled(stretch: Stretch, global_map: Path, tile_size: float) -> Stretch:
    """``stretch`` with its map ``global_map`` cut into tiles of ``tile_size`` [m], in a window of about the same
    extent."""
    www = stretch.tiles.parent.with_name(f"{stretch.tiles.parent.name}_{tile_size:g}m")
    www.mkdir()
    tile_map([global_map], www / "map", TileConfig(grid_size=tile_size, progress=False))
    half_window = round((2 * stretch.half_window + 1) * stretch.tile_size / tile_size - 1) // 2
    return Stretch(f"{stretch.name}_{tile_size:g}m", stretch.data, www / "map", tile_size, half_window)


def square_tiles(tiles: Path, centre: np.ndarray, half: float) -> int:
    """Tiles in the index of ``tiles`` that meet the square of half side ``half`` [m] about ``centre`` (x y)."""
    d = open_tile_directory(tiles)
    s = d.grid_size
    low = [math.floor((c - half) / s) for c in centre]
    high = [math.ceil((c + half) / s) - 1 for c in centre]
    return len(d.codes_in_box(low[0], high[0], low[1], high[1]))


def first_position(data: Path) -> np.ndarray:
    """x y [m] of the first scan's reference pose in bench_localizer's input (format in bench_localizer.cpp)."""
    with data.open("rb") as f:
        f.seek(16)  # magic, rate
        (n_map,) = np.frombuffer(f.read(8), "<u8")
        f.seek(int(n_map) * 12 + 16 * 8, os.SEEK_CUR)  # the map, base_T_sensor
        (n_imu,) = np.frombuffer(f.read(8), "<u8")
        f.seek(int(n_imu) * 32 + 8 + 8, os.SEEK_CUR)  # the gyro samples, the scan count, the stamp
        truth = np.frombuffer(f.read(16 * 8), "<f8").reshape(4, 4)
    return truth[:2, 3].copy()


def read_trace(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    columns = ("scan_ms", "published", "lost", "error_m", "x", "y", "monotonic_s", "truth_x", "truth_y")
    columns += ("tiles_in_flight", "tiles_awaited", "start_tiles_in_flight", "scan_square_tiles_in_flight")
    return {name: np.array([float(r[name]) for r in rows]) for name in columns}


def rmse(values: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def figures(trace: dict, summary: dict, disk: dict | None, bound_rate: float | None, square: int) -> dict:
    """The run's figures and targets (module docstring); ``disk`` is the disk run's trace (None: this is it)."""
    published = trace["published"] > 0
    start = trace["monotonic_s"][0] - trace["scan_ms"][0] / 1e3  # when the first scan was handed over
    first = int(np.argmax(published)) if published.any() else None
    window = summary["first_window"]
    measured_rate = window["tiles"] / (window["load_ms"] / 1e3) if window["load_ms"] > 0 else None
    rate = bound_rate if bound_rate is not None else measured_rate
    bound = square / rate + BOUND_SLACK_S if rate else None
    row: dict = {
        "first_window_tiles": window["tiles"],
        "first_window_load_s": rounded(window["load_ms"] / 1e3, 2),
        "measured_fetch_rate_tiles_s": rounded(measured_rate, 1),
        "start_square_tiles": square,
        "first_pose_s": rounded(trace["monotonic_s"][first] - start, 2) if first is not None else None,
        "first_pose_bound_s": rounded(bound, 2),
        "first_pose_scan": first,
        "scans": int(published.size),
    }
    error = trace["error_m"]
    if first is not None:
        # The drive goes on while the start's tiles arrive: how far the car had gone by the first pose.
        truth = np.column_stack([trace["truth_x"], trace["truth_y"]])
        row["moved_before_first_pose_m"] = rounded(np.linalg.norm(truth[first] - truth[0]), 1)
        row["first_pose_error_m"] = rounded(error[first])
    # Until the start square is whole for the first time (later the window may follow the pose away and back).
    whole = np.flatnonzero(trace["start_tiles_in_flight"] == 0)
    start_whole = int(whole[0]) if whole.size else published.size
    row["start_square_whole_s"] = rounded(trace["monotonic_s"][start_whole] - start, 2) if whole.size else None
    # The tiles under a scan: those meeting the square of map_wait_half_side about its true position.
    missing = trace["scan_square_tiles_in_flight"] > 0
    row["first_pose_tiles_missing"] = int(trace["scan_square_tiles_in_flight"][first]) if first is not None else None
    row["published_with_tiles_missing"] = int((published & missing).sum())
    row["max_error_m"] = rounded(error[published].max()) if published.any() else None
    lost = trace["lost"] > 0
    in_flight = trace["tiles_in_flight"] > 0
    row["lost_scans"] = int(lost.sum())
    row["lost_while_tiles_in_flight"] = int((lost & in_flight).sum())
    row["lost_while_tiles_awaited"] = int((lost & (trace["tiles_awaited"] > 0)).sum())
    row["waited_scans_after_first_pose"] = (
        int((~published[first:] & (trace["tiles_awaited"][first:] > 0)).sum()) if first is not None else None
    )
    if first is None:
        row.update(scans_with_pose=0.0, rmse_m=None)
        if disk is not None:
            row["targets"] = {"all_met": False}
        return row
    after = np.arange(published.size) >= first
    row["scans_with_pose"] = rounded(published[after].mean(), 4)
    row["rmse_m"] = rounded(rmse(error[after & published]), 4)
    if disk is None:
        return row
    disk_published = disk["published"] > 0
    row["disk_scans_with_pose"] = rounded(disk_published[after].mean(), 4)
    row["disk_rmse_m"] = rounded(rmse(disk["error_m"][after & disk_published]), 4)
    both = published & disk_published
    row["rmse_to_disk_m"] = rounded(rmse(np.hypot(trace["x"] - disk["x"], trace["y"] - disk["y"])[both]), 4)
    row["lost_from_tiles_in_flight"] = int((lost & in_flight & ~(disk["lost"] > 0)).sum())
    targets = {
        "nothing_published_before_its_tiles": row["first_pose_tiles_missing"] == 0,
        "never_more_than_1m_off": row["max_error_m"] <= MAX_ERROR_M,
        "first_pose_within_bound": bound is not None and row["first_pose_s"] <= bound,
        "scans_with_pose_within_1pct_of_disk": abs(row["scans_with_pose"] - row["disk_scans_with_pose"])
        <= SHARE_TOLERANCE,
        "rmse_within_1cm_of_disk": row["disk_rmse_m"] is not None
        and abs(row["rmse_m"] - row["disk_rmse_m"]) <= RMSE_TOLERANCE_M,
        "no_lost_from_tiles_in_flight": row["lost_from_tiles_in_flight"] == 0,
    }
    row["targets"] = {**targets, "all_met": all(targets.values())}
    return row


def run_stretch(
    stretch: Stretch, rates: tuple[float, ...], python_server: bool, bin_dir: Path, tmp: Path, traces: Path
) -> None:
    """The disk run, then each store, on ``stretch``; prints one JSON line per run, and keeps each run's per-scan
    trace (bench_localizer's CSV) in ``traces``."""
    revision = "sha256:" + hashlib.sha256((stretch.tiles / "index.json").read_bytes()).hexdigest()[:16]
    runs = 0

    def drive(source: str, cache: Path | None, store: str) -> tuple[dict, dict]:
        nonlocal runs
        runs += 1
        trace = traces / f"{stretch.name}_{store}.csv"
        cmd = [str(bin_dir / "bench_localizer"), str(stretch.data), "tiles", "--tile-size", str(stretch.tile_size)]
        cmd += ["--window", str(stretch.half_window), "--tile-source", source, "--index-revision", revision]
        cmd += ["--trace", str(trace), "--cold-start", "1", "--pace", "stamps"]
        if cache is not None:
            cmd += ["--map-store-cache", str(cache)]
        done = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True)  # its stderr is ours
        return json.loads(done.stdout), read_trace(trace)

    def report(store: str, rate: float | None, summary: dict, trace: dict, disk: dict | None, square: int) -> None:
        row = {"bench": BENCH, "store": store, "rate_tiles_s": rate, "stretch": stretch.name}
        if store != "disk":  # the round trip the proxy adds to each request (none without it)
            row["added_latency_ms"] = 0.0 if rate is None else 2e3 * ONE_WAY_DELAY_S
        row.update(figures(trace, summary, disk, rate, square))
        row.update(
            repeats=1,
            tile_size_m=stretch.tile_size,
            window_tiles=summary["window_tiles"],
            distance_m=summary["distance_m"],
            tiles_fetched=summary["map_store"]["tiles_fetched"],
            # over the drive (the window follows the car: more than its first window)
            fetched_tiles_per_s=rounded(
                summary["map_store"]["tiles_fetched"] / (trace["monotonic_s"][-1] - trace["monotonic_s"][0]), 1
            ),
            map_update_failures=summary["map_update_failures"],
            ndt_threads=summary["ndt_threads"],
            map_update_threads=summary["map_update_threads"],
            cpu_model=cpu_model(),
            cores=os.cpu_count(),
            load_average_1min=os.getloadavg()[0],
        )
        print(json.dumps(row), flush=True)

    square = square_tiles(stretch.tiles, first_position(stretch.data), START_HALF_SIDE)
    summary, disk = drive(str(stretch.tiles), None, "disk")
    if summary["first_window"]["start_square_tiles"] != square:  # the index and bench_localizer's own cut agree
        raise RuntimeError(f"{stretch.name}: the start square holds {square} tiles of index.json, {summary}")
    report("disk", None, summary, disk, None, square)
    server = nginx_server.NginxServer(stretch.tiles.parent)
    server.start()
    try:
        for rate in rates:
            proxy = DelayProxy(server.port, ONE_WAY_DELAY_S, rate_requests_s=rate)
            proxy.start()
            try:
                url = f"http://127.0.0.1:{proxy.port}/{stretch.tiles.name}"
                summary, trace = drive(url, tmp / f"{stretch.name}_cache_{runs}", f"nginx_{rate:g}")
            finally:
                proxy.stop()
            report("nginx_throttled", rate, summary, trace, disk, square)
    finally:
        server.close()
    if python_server:
        with python_http_server(stretch.tiles.parent) as port:
            url = f"http://127.0.0.1:{port}/{stretch.tiles.name}"
            summary, trace = drive(url, tmp / f"{stretch.name}_cache_{runs}", "python_http_server")
        report("python_http_server", None, summary, trace, disk, square)


def run(bin_dir: Path, quick: bool, street: Stretch | None = None, traces: Path | None = None) -> None:
    """Part 3 of bench_map_store.py: the kitti00_far stretches (or, ``quick``, ``street`` at QUICK_RATE only). The
    runs' per-scan traces are kept in ``traces`` when given."""
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        if traces is None:
            traces = tmp
        traces.mkdir(parents=True, exist_ok=True)
        if quick:
            assert street is not None
            run_stretch(street, (QUICK_RATE,), False, bin_dir, tmp, traces)
            return
        if not (KITTI / "scans").is_dir():
            message = f"the kitti00_far keyframes are not at {KITTI} (the team's real data, ../shared beside the clone"
            print(json.dumps({"bench": BENCH, "skipped": message + ", or GPL_SHARED_DATA)"}), flush=True)
            return
        for name in STRETCHES:
            stretch = kitti_stretch(name, tmp)
            run_stretch(stretch, RATES, True, bin_dir, tmp, traces)
            car = retiled(stretch, tmp / f"kitti_{name}" / "global_map.pcd", CAR_TILE_SIZE)
            run_stretch(car, CAR_TILE_RATES, False, bin_dir, tmp, traces)
