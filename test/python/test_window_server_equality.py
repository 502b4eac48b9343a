"""The provider nodelet's C++ WindowServer against the rospy provider's Python one (the reference): the same
windows, sectors, tile sets, ``added``, ``removed`` and ``prefetch`` (as tile names) on random pose sequences,
headings, presets, tile sides and window sequences, with headings on and next to every Table I boundary, lost
searches and resets. The C++ side runs as test/cpp/window_server_replay, built with the tests."""

from __future__ import annotations

import json
import math
import random
import subprocess
from pathlib import Path

import pytest

from grid_puzzle_localization.provider.lost_search import SearchRegion
from grid_puzzle_localization.provider.tile_references import TileReferences
from grid_puzzle_localization.provider.window import (
    SECTOR_BOUNDS_DEG,
    PoseSample,
    WindowConfig,
    WindowTracker,
)
from grid_puzzle_localization.provider.window_server import WindowServer
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiles.grid import tile_stem

POSES_PER_SEQUENCE = 700  # 15 sequences: 10,500 poses
# (tile side [m], window config, lost max half side [m], directory with an index (its tiles in key order as the tiler
# writes them, or shuffled) or scanned)
SEQUENCES = [
    (2.0, WindowConfig(preset="urban"), 100.0, "index"),
    (2.0, WindowConfig(preset="courtyard"), 60.0, "scan"),
    (2.0, WindowConfig(preset="courtyard", heading_source="yaw"), 40.0, "index"),
    (0.5, WindowConfig(n=6, k=4), 10.0, "scan"),
    (0.2, WindowConfig(n=5, k=3, heading_source="yaw"), 5.0, "index"),
    (2.5, WindowConfig(n=3, k=7, lookahead_time=1.5), 30.0, "scan"),
    (1.0, WindowConfig(n=0, k=2, update_distance=0.3), 0.0, "index"),
    (10.0, WindowConfig(n=2, k=1, lookahead_time=0.8, heading_source="yaw"), 50.0, "scan"),
    (2.0, WindowConfig(n=4, k=0), 20.0, "shuffled index"),
    (0.7, WindowConfig(n=8, k=5, update_distance=2.0), 15.0, "scan"),
    (3.0, WindowConfig(n=1, k=3), 25.0, "index"),
    (2.0, WindowConfig(n=10, k=6, heading_source="yaw", lookahead_time=0.5), 35.0, "scan"),
    (1.5, WindowConfig(n=2, k=2), 12.0, "shuffled index"),
    (5.0, WindowConfig(n=3, k=4, heading_source="yaw"), 45.0, "scan"),
    (2.0, WindowConfig(n=7, k=9, lookahead_time=2.0), 70.0, "index"),
]
# Headings on, just below and just above each Table I boundary [deg], one turn apart too.
BOUNDARY_DEGREES = [
    b + d + turn for b in SECTOR_BOUNDS_DEG for d in (0.0, -1e-7, 1e-7) for turn in (0.0, 360.0, -360.0)
]


def replay_program() -> Path:
    from catkin.find_in_workspaces import find_in_workspaces

    found = find_in_workspaces(
        search_dirs=["libexec"], project="grid_puzzle_localization", path="window_server_replay", first_match_only=True
    )
    assert found, "window_server_replay is not built: run `make build` (it is built with the tests)"
    return Path(found[0])


def make_tile_dir(root: Path, s: float, source: str, rng: random.Random) -> Path:
    """About 60 % of the tiles of an area 120 tiles on a side, as empty files (scan) or an index."""
    root.mkdir()
    keys = [(i, j) for i in range(-60, 60) for j in range(-60, 60) if rng.random() < 0.6]
    if source == "scan":
        for i, j in keys:
            (root / f"{tile_stem(i, j, s)}.pcd").touch()
        (root / "notes.pcd").touch()  # not a tile name: both sides must ignore it
    else:
        tiles = [{"key": [i, j], "stem": tile_stem(i, j, s), "file": f"{tile_stem(i, j, s)}.pcd"} for i, j in keys]
        if source == "shuffled index":
            rng.shuffle(tiles)
        index = {"format": "grid_puzzle_tiles", "version": 1, "grid_size": s, "origin": [0.0, 0.0], "tiles": tiles}
        (root / "index.json").write_text(json.dumps(index))
    return root


def random_commands(s: float, rng: random.Random) -> list[dict]:
    """A random drive: steps below and above the update distance, turns, stops, jumps, headings on the Table I
    boundaries, yaws and velocities sometimes missing, lost searches and their end, whole-window resends and the whole
    map of a start without a pose."""
    x, y, t, heading = rng.uniform(-40, 40) * s, rng.uniform(-40, 40) * s, 0.0, rng.uniform(-math.pi, math.pi)
    commands: list[dict] = []
    poses = 0
    while poses < POSES_PER_SEQUENCE:
        roll = rng.random()
        if roll < 0.03:
            r = rng.uniform(0.0, 30.0 * s)
            commands.append(
                {"search": {"x": x + rng.gauss(0, 3 * s), "y": y + rng.gauss(0, 3 * s), "radius": r, "t": t}}
            )
            continue
        if roll < 0.05:
            commands.append({"end_search": True})
            continue
        if roll < 0.06:
            # The whole map is held until the localizer tracks: ended at once, so the drive goes on serving windows.
            commands.extend([{"whole_map": True}, {"end_search": True}] if roll < 0.052 else [{"whole": True}])
            continue
        if roll < 0.25:
            heading = math.radians(rng.choice(BOUNDARY_DEGREES))
        elif roll < 0.6:
            heading += rng.gauss(0.0, 0.6)
        step = rng.choice([rng.uniform(0.0, 0.6 * s), rng.uniform(0.4 * s, 3.0 * s)])
        if rng.random() < 0.02:
            step = rng.uniform(10, 60) * s  # a jump (a relocalisation)
        x += step * math.cos(heading)
        y += step * math.sin(heading)
        t += rng.uniform(0.05, 0.5)
        yaw = None if rng.random() < 0.15 else heading + rng.choice([0.0, 0.0, rng.gauss(0, 0.2)])
        velocity = None if rng.random() < 0.5 else [rng.gauss(0, 3), rng.gauss(0, 3)]
        commands.append({"pose": {"x": x, "y": y, "t": t, "yaw": yaw, "velocity": velocity}})
        poses += 1
    return commands


def window_json(window) -> dict:
    return {
        "bounds": list(window.bounds),
        "sector": window.sector,
        "theta": window.theta if math.isfinite(window.theta) else None,
    }


def reference_outputs(tile_dir: Path, s: float, config: WindowConfig, max_half_side: float, commands) -> list:
    directory = open_tile_directory(tile_dir, s)
    server = WindowServer(WindowTracker(config, s), TileReferences(directory), max_half_side)

    def stems(keys):
        return [tile_stem(i, j, s) for i, j in keys]

    def served_json(served):
        if served is None:
            return None
        out = window_json(served.window)
        out.update(
            first=served.first,
            changed=served.changed,
            added=stems(served.delta.added),
            removed=stems(served.delta.removed),
            prefetch=stems(served.delta.prefetch),
        )
        return out

    outputs = []
    for cmd in commands:
        if "pose" in cmd:
            p = cmd["pose"]
            velocity = tuple(p["velocity"]) if p["velocity"] is not None else None
            outputs.append(served_json(server.on_pose(PoseSample(p["x"], p["y"], p["t"], p["yaw"], velocity))))
        elif "search" in cmd:
            r = cmd["search"]
            outputs.append(served_json(server.on_search(SearchRegion(r["x"], r["y"], r["radius"], r["t"]))))
        elif "end_search" in cmd:
            server.end_search()
            outputs.append(None)
        elif "whole_map" in cmd:
            outputs.append(served_json(server.on_whole_map()))
        else:
            whole = server.whole()
            if whole is None:
                outputs.append(None)
            else:
                window, delta = whole
                outputs.append(window_json(window) | {"added": stems(delta.added), "prefetch": stems(delta.prefetch)})
    return outputs


def cpp_outputs(tile_dir: Path, s: float, config: WindowConfig, max_half_side: float, commands) -> list:
    setup = {
        "dir": str(tile_dir),
        "grid_size": s,
        "max_half_side": max_half_side,
        "window": {
            "n": config.n,
            "k": config.k,
            "update_distance": config.update_distance,
            "heading_source": config.heading_source,
            "lookahead_time": config.lookahead_time,
            "preset": config.preset,
        },
    }
    text = "\n".join(json.dumps(line) for line in [setup, *commands]) + "\n"
    done = subprocess.run([str(replay_program())], input=text, capture_output=True, text=True, check=True)
    return [json.loads(line) for line in done.stdout.splitlines()]


@pytest.mark.parametrize("case", range(len(SEQUENCES)))
def test_cpp_window_server_equals_python(case, tmp_path):
    s, config, max_half_side, source = SEQUENCES[case]
    rng = random.Random(1000 + case)
    tile_dir = make_tile_dir(tmp_path / "tiles", s, source, rng)
    commands = random_commands(s, rng)
    expected = reference_outputs(tile_dir, s, config, max_half_side, commands)
    got = cpp_outputs(tile_dir, s, config, max_half_side, commands)
    assert len(got) == len(expected)
    sectors = {e["sector"] for e in expected if e is not None}
    assert sectors >= set(range(8)), f"the sequence must use every Table I sector (used {sorted(sectors)})"
    for n, (cmd, e, g) in enumerate(zip(commands, expected, got)):
        assert g == e, f"command {n} {cmd}: C++ {g} != Python {e}"
