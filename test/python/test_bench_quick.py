"""Smoke runs of the benchmarks' --quick modes: they run end to end and what they report is consistent
(the drive is tracked, tiles travel by reference and are tile-aligned, deltas arrive in order). No figure
of speed or memory is asserted: those are the benchmarks' to report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench"


def run_bench(name: str) -> list[dict]:
    out = subprocess.run(
        [sys.executable, str(BENCH / name), "--quick"], check=True, capture_output=True, text=True, timeout=600
    ).stdout
    return [json.loads(line) for line in out.splitlines() if line.strip()]


def test_bench_scaling_quick_tracks_the_drive_in_both_modes_at_every_size():
    assert os.environ.get("GPL_WS"), "source tools/env.sh (GPL_WS locates bench_scaling)"
    lines = run_bench("bench_scaling.py")
    runs = [r for r in lines if r["bench"] == "scaling"]
    assert sorted((r["factor"], r["mode"]) for r in runs) == sorted(
        (f, m) for f in (1, 4, 16) for m in ("global", "tiles")
    )
    for r in runs:
        assert r["tracked"] == r["scans"] > 0, r
        assert r["worst_error_m"] < 0.1, r
    for factor in (1, 4, 16):
        glob, tiles = (next(r for r in runs if r["factor"] == factor and r["mode"] == m) for m in ("global", "tiles"))
        assert glob["map_points"] == tiles["map_points"]
        assert tiles["tile_aligned"] and tiles["tiles_read"] > 0
        assert tiles["target_points_first"] < glob["target_points_first"]
    # The map grows with the factor; the window does not (the quick crop is smaller than the window, which
    # reaches into the neighbouring copies of the 2 x 2 grid but no farther).
    points = {r["factor"]: r["target_points_first"] for r in runs if r["mode"] == "global"}
    assert points[16] == 16 * points[1]
    window = {r["factor"]: r["target_points_first"] for r in runs if r["mode"] == "tiles"}
    assert window[16] == window[4] > window[1]
    assert lines[-1]["bench"] == "scaling_summary"


def test_bench_provider_quick_drives_the_node_with_deltas_in_order():
    (result,) = run_bench("bench_provider.py")
    drive = result["sparse"]["drive"]
    assert drive["delta_revisions_contiguous"] and drive["deltas_received"] > 3
    assert drive["tiles_prefetch_per_update"]["max"] > 0
    assert result["sparse"]["drive_with_map_cloud_subscriber"]["map_clouds_received"] > 0
