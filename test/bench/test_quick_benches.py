"""Every `make bench-*` target in its quick mode (a few seconds on tiny inputs, no ../shared data), so a broken
benchmark fails `make test` (tools/run_tests.sh bench). Each must exit 0 and print one JSON object per line, and
what some of them report must be consistent (the drive is tracked, tiles travel by reference and are tile-aligned,
deltas arrive in order). No figure of speed or memory is judged here: that is the full benchmarks' to report."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("GPL_WS", "")) / "devel" / "lib" / "grid_puzzle_localization"

# The one list of benchmarks: make target -> its quick command.
QUICK = {
    "bench-tiling": [sys.executable, str(ROOT / "bench/bench_tiling.py"), "--quick"],
    "bench-provider": [sys.executable, str(ROOT / "bench/bench_provider.py"), "--quick"],
    "bench-ndt": [str(BIN / "bench_ndt"), "--quick"],
    "bench-map-store": [sys.executable, str(ROOT / "bench/bench_map_store.py"), "--quick"],
    "bench-map-worker": [sys.executable, str(ROOT / "bench/bench_map_worker.py"), "--quick"],
    "bench-localizer": [sys.executable, str(ROOT / "bench/bench_localizer.py"), "--quick"],
    "bench-sim": [sys.executable, str(ROOT / "bench/bench_sim.py"), "--quick"],
    "bench-blocks": [sys.executable, str(ROOT / "bench/bench_blocks.py"), "--quick"],
    "bench-monitor": [sys.executable, str(ROOT / "bench/bench_monitor.py"), "--quick"],
    "bench-scaling": [sys.executable, str(ROOT / "bench/bench_scaling.py"), "--quick"],
    "bench-global-localization": [sys.executable, str(ROOT / "bench/bench_global_localization.py"), "--quick"],
}
TIMEOUT_S = 300  # generous on a shared 2-core machine; a quick mode takes seconds


def make_bench_targets() -> set[str]:
    return set(re.findall(r"^(bench-[\w-]+):", (ROOT / "Makefile").read_text(), flags=re.MULTILINE))


def test_every_make_bench_target_has_a_quick_mode_here():
    assert make_bench_targets() == set(QUICK)


@pytest.fixture(scope="module")
def quick_output(tmp_path_factory):
    """Each quick mode's JSON lines, run once for this module and shared by the tests below."""
    outputs: dict[str, list[dict]] = {}

    def run(target: str) -> list[dict]:
        if target not in outputs:
            env = {**os.environ, "TMPDIR": str(tmp_path_factory.mktemp(target))}
            done = subprocess.run(QUICK[target], cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
            assert done.returncode == 0, f"{target} --quick failed ({done.returncode}):\n{done.stderr[-3000:]}"
            lines = [line for line in done.stdout.splitlines() if line.strip()]
            assert lines, f"{target} --quick printed nothing"
            rows = [json.loads(line) for line in lines]  # one JSON document per line, never an indented one
            for line, row in zip(lines, rows):
                assert isinstance(row, dict), f"{target} printed a line that is not a JSON object: {line}"
            outputs[target] = rows
        return outputs[target]

    return run


@pytest.mark.parametrize("target", sorted(QUICK))
def test_quick_mode_prints_json_lines(target, quick_output):
    assert quick_output(target)


def test_bench_scaling_quick_tracks_the_drive_in_both_modes_at_every_size(quick_output):
    lines = quick_output("bench-scaling")
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


def test_bench_provider_quick_drives_the_node_with_deltas_in_order(quick_output):
    (result,) = quick_output("bench-provider")
    drive = result["sparse"]["drive"]
    assert drive["delta_revisions_contiguous"] and drive["deltas_received"] > 3
    assert drive["tiles_prefetch_per_update"]["max"] > 0
    assert result["sparse"]["drive_with_map_cloud_subscriber"]["map_clouds_received"] > 0


def test_bench_map_worker_quick_reports_the_worker_per_metre_and_fewer_updates_further_apart(quick_output):
    rows = quick_output("bench-map-worker")
    runs = {row["update_distance_m"]: row for row in rows if not row.get("summary")}
    assert set(runs) == {5.0, 20.0}
    for row in runs.values():
        assert row["distance_m"] > 0 and row["map_worker_cpu_ms_per_m"] > 0
        assert row["read_cpu_ms"] + row["fold_cpu_ms"] <= row["map_worker_cpu_ms"]
        assert row["max_error_m"] < 0.1  # the drive is tracked whatever the distance
    assert runs[20.0]["window_updates"] < runs[5.0]["window_updates"]
    summaries = [row for row in rows if row.get("summary")]
    assert [s["update_distance_m"] for s in summaries] == [5.0, 20.0]
