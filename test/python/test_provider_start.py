"""A provider start without a pose: the hint's search region and the whole map (provider/window_server.py; the C++
twin is held equal by test_window_server_equality)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from grid_puzzle_localization.provider.lost_search import HINT_SIGMAS, SearchRegion, hint_region
from grid_puzzle_localization.provider.tile_references import TileReferences
from grid_puzzle_localization.provider.window import PoseSample, WindowConfig, WindowTracker
from grid_puzzle_localization.provider.window_server import WindowServer
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiles.grid import tile_stem

S = 2.0
# An L-shaped map: tiles i 0..29, j 0..9 and i 0..9, j 10..39 (bounding box 60 m x 80 m).
KEYS = [(i, j) for i in range(30) for j in range(10)] + [(i, j) for i in range(10) for j in range(10, 40)]


@pytest.fixture
def server(tmp_path: Path) -> WindowServer:
    for i, j in KEYS:
        (tmp_path / f"{tile_stem(i, j, S)}.pcd").touch()
    directory = open_tile_directory(tmp_path, S)
    return WindowServer(WindowTracker(WindowConfig(n=3, k=2), S), TileReferences(directory), 100.0)


def test_hint_region_reaches_three_sigmas_of_the_larger_variance():
    region = hint_region(10.0, -5.0, 16.0, 100.0, 3.5)
    assert region == SearchRegion(10.0, -5.0, HINT_SIGMAS * 10.0, 3.5)
    assert hint_region(1.0, 2.0, 0.0, -1.0, 0.0).radius == 0.0  # no covariance: the localizer's own square
    assert hint_region(1.0, 2.0, math.nan, 4.0, 0.0).radius == 0.0
    for x, y in ((math.nan, 0.0), (0.0, math.inf)):
        with pytest.raises(ValueError, match="not finite"):
            hint_region(x, y, 1.0, 1.0, 0.0)


def test_whole_map_serves_every_tile_once_and_holds_until_the_localizer_tracks(server: WindowServer):
    assert server.map_area() == pytest.approx(30 * 40 * S * S)
    served = server.on_whole_map(7.0)
    assert served is not None and served.first and served.changed
    assert sorted(served.delta.added) == sorted(KEYS)
    assert server.on_whole_map() is None  # served already
    assert server.on_pose(PoseSample(5.0, 5.0, 8.0, 0.0)) is None  # held: no pose is tracked yet
    server.end_search()
    after = server.on_pose(PoseSample(5.0, 5.0, 9.0, 0.0))
    assert after is not None and len(after.delta.removed) > 0 and not after.delta.added


def test_touches_map_is_the_square_of_the_radius_against_the_tiles_box(server: WindowServer):
    # The tiles' box is x 0..60 m, y 0..80 m.
    assert server.touches_map(SearchRegion(30.0, 40.0, 0.0, 0.0))
    assert server.touches_map(SearchRegion(-10.0, 40.0, 10.0, 0.0))  # reaches x = 0
    assert not server.touches_map(SearchRegion(-10.1, 40.0, 10.0, 0.0))
    assert not server.touches_map(SearchRegion(30.0, 200.0, 100.0, 0.0))
    assert server.touches_map(SearchRegion(70.0, 90.0, 10.0, 0.0))  # the corner (60, 80)


def distances(keys: list[tuple[int, int]], x: float, y: float) -> list[float]:
    return [math.hypot((i + 0.5) * S - x, (j + 0.5) * S - y) for i, j in keys]


def test_tiles_go_out_nearest_the_pose_or_the_search_centre_first(server: WindowServer):
    """The localizer loads a delta's tiles in its order: the tiles under the scan come first (issue 58)."""
    search = server.on_search(SearchRegion(13.0, 9.0, 8.0, 1.0))
    assert search is not None
    assert distances(search.delta.added, 13.0, 9.0) == sorted(distances(search.delta.added, 13.0, 9.0))
    _, whole = server.whole()
    assert distances(whole.added, 13.0, 9.0) == sorted(distances(whole.added, 13.0, 9.0))
    server.end_search()
    moved = server.on_pose(PoseSample(41.0, 7.0, 2.0, 0.0))
    assert moved is not None and moved.delta.added
    assert distances(moved.delta.added, 41.0, 7.0) == sorted(distances(moved.delta.added, 41.0, 7.0))
