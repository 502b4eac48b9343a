"""Tile directory and store: the loaded set after random paths against a brute-force selection over the
directory listing, deltas replayed against the files, the cache, and the error cases."""

import math

import numpy as np
import pytest
from fixtures.synthetic_tiles import write_tiles
from tile_truth import brute_force_window_files

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.provider.tile_store import TileStore
from grid_puzzle_localization.provider.window import PoseSample, WindowConfig, WindowTracker, compute_window
from grid_puzzle_localization.tiles.directory import open_tile_directory

S = 2.0


@pytest.fixture(scope="module")
def holey_map(tmp_path_factory):
    """A 24 x 20 tile map around the origin with 30 % of the tiles missing and some foreign files."""
    d = tmp_path_factory.mktemp("tiles")
    rng = np.random.default_rng(1)
    keys = [(i, j) for i in range(-12, 12) for j in range(-8, 12) if rng.random() > 0.3]
    write_tiles(d, keys, S, count=20, seed=2)
    for foreign in ("README.pcd", "2.0_3.0.pcd", "1.0_3.pcd", "notes.txt"):
        (d / foreign).write_text("not a tile")
    return d


def file_xyz(path):
    """x, y, z of a tile file as float32 records, through the general PCD reader."""
    points = read_pcd(path).points
    out = np.empty(len(points), dtype=XYZ_DTYPE)
    for name in "xyz":
        out[name] = points[name]
    return out


def random_path(rng, steps):
    x, y = rng.uniform(-10, 10, 2).tolist()
    heading = rng.uniform(-math.pi, math.pi)
    for _ in range(steps):
        if rng.random() < 0.15:
            heading += rng.uniform(-2.0, 2.0)
        step = rng.choice([0.0, 0.3, 1.5, 3.0])  # standing, creeping, driving
        x += step * math.cos(heading)
        y += step * math.sin(heading)
        if abs(x) > 40 or abs(y) > 40:  # wander off the map and come back
            heading += math.pi
        yield x, y


def test_directory_scan_reports_foreign_names(holey_map):
    d = open_tile_directory(holey_map, S)
    assert d.source == "scan"
    assert d.unparsable == ("1.0_3.pcd", "2.0_3.0.pcd", "README.pcd")
    everything = compute_window(0.0, 0.0, None, S, 100, 0)
    assert {tuple(k) for k in d.existing_in(everything).tolist()} == brute_force_window_files(
        holey_map, everything.bounds, S
    )


@pytest.mark.parametrize("seed", range(6))
def test_loaded_set_equals_window_and_listing_after_random_paths(holey_map, seed):
    rng = np.random.default_rng(seed)
    store = TileStore(open_tile_directory(holey_map, S), cache_mb=0.05 if seed % 2 else 8.0)
    tracker = WindowTracker(WindowConfig(n=2, k=3), S)
    mirror = {}  # replays the deltas, as a subscriber would
    try:
        for x, y in random_path(rng, 150):
            window = tracker.update(PoseSample(x, y))
            if window is None:
                continue
            delta = store.update(window, tracker.predicted_windows())
            for key in delta.removed:
                del mirror[key]
            for key, points in delta.added:
                assert key not in mirror
                mirror[key] = points
            truth = brute_force_window_files(holey_map, window.bounds, S)
            assert {k for k, _ in store.loaded()} == truth
            assert set(mirror) == truth
            assert store.stats().cache_bytes <= store.cache_limit
        for key, points in mirror.items():
            assert points.dtype == XYZ_DTYPE
            assert file_xyz(store.directory.tile_path(key)).tobytes() == points.tobytes()
    finally:
        store.close()


def test_straight_drive_is_served_from_the_prefetch_cache(holey_map):
    store = TileStore(open_tile_directory(holey_map, S), cache_mb=8.0)
    tracker = WindowTracker(WindowConfig(n=2, k=2), S)
    misses_after_start = 0
    try:
        for step in range(30):
            window = tracker.update(PoseSample(-20.0 + 1.5 * step, 1.0))
            delta = store.update(window, tracker.predicted_windows())
            if step >= 2:
                misses_after_start += delta.misses
            assert store.wait_prefetch_idle(timeout=30.0)
        stats = store.stats()
        assert misses_after_start == 0
        assert stats.cache_hits > 0 and stats.prefetched > 0
    finally:
        store.close()


def test_tiles_left_behind_never_evict_tiles_read_ahead(tmp_path):
    """A cache that holds little more than the next column: tiles leaving the window must not push
    out the column the prefetcher read for the next update."""
    write_tiles(tmp_path, [(i, j) for i in range(40) for j in range(11)], S, count=20)  # 240 B of x y z
    tile_bytes = 20 * XYZ_DTYPE.itemsize
    store = TileStore(open_tile_directory(tmp_path, S), cache_mb=12 * tile_bytes / 2**20)
    tracker = WindowTracker(WindowConfig(n=2, k=2), S)
    misses = []
    try:
        for step in range(40):
            window = tracker.update(PoseSample(1.0 + 1.5 * step, 11.0))  # rows 3..7; turns reach 1..9
            if window is None:
                continue
            delta = store.update(window, tracker.predicted_windows())
            misses.append(delta.misses)
            assert store.wait_prefetch_idle(timeout=30.0)
        assert sum(misses[2:]) == 0 and store.stats().cache_hits > 0
    finally:
        store.close()


def test_u_turn_is_served_from_the_cache_without_prefetch(holey_map):
    store = TileStore(open_tile_directory(holey_map, S), cache_mb=8.0, prefetch=False)
    try:
        first = store.update(compute_window(1.0, 1.0, None, S, 2, 0))
        store.update(compute_window(21.0, 1.0, None, S, 2, 0))  # all tiles leave the window
        back = store.update(compute_window(1.0, 1.0, None, S, 2, 0))
        assert back.misses == 0 and back.hits == len(first.added) > 0
    finally:
        store.close()


def test_corrupt_tile_is_skipped_and_reported_once(tmp_path):
    keys = [(i, j) for i in range(4) for j in range(4)]
    write_tiles(tmp_path, keys, S, count=10)
    bad = open_tile_directory(tmp_path, S).tile_path((1, 1))
    bad.write_bytes(bad.read_bytes()[:-7])  # truncated
    store = TileStore(open_tile_directory(tmp_path, S), cache_mb=1.0)
    try:
        reports = []
        for x in (1.0, 3.5, 1.0, 6.5, 1.0):
            delta = store.update(compute_window(x, 1.0, None, S, 1, 0))
            reports += delta.newly_corrupt
            assert (1, 1) not in {k for k, _ in store.loaded()}
        assert [p for p, _ in reports] == [bad]
        assert "truncated" in reports[0][1]
        assert store.stats().corrupt == [str(bad)]
    finally:
        store.close()


@pytest.fixture
def mixed_fields(tmp_path):
    """Tile (0, 0) with x y z intensity (5 points), tile (1, 0) with x y z only (3 points)."""
    write_tiles(tmp_path, [(0, 0)], S, count=5)
    from grid_puzzle_localization.pcd import write_pcd

    odd = np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    odd["x"] = 3.0
    write_pcd(tmp_path / "3.0_1.0.pcd", odd)
    return tmp_path


def test_all_fields_kept_on_request_and_a_tile_with_other_fields_is_reported_not_merged(mixed_fields):
    store = TileStore(open_tile_directory(mixed_fields, S), prefetch=False, xyz_only=False)
    try:
        delta = store.update(compute_window(1.0, 1.0, None, S, 1, 0))
        assert [k for k, _ in delta.added] == [(0, 0)]
        assert len(delta.newly_corrupt) == 1 and "differ" in delta.newly_corrupt[0][1]
        assert store.merged().tobytes() == read_pcd(mixed_fields / "1.0_1.0.pcd").points.tobytes()
        assert store.dtype.names == ("x", "y", "z", "intensity")
    finally:
        store.close()


def test_xyz_only_store_merges_tiles_of_any_fields(mixed_fields):
    store = TileStore(open_tile_directory(mixed_fields, S), prefetch=False)
    try:
        delta = store.update(compute_window(1.0, 1.0, None, S, 1, 0))
        assert sorted(k for k, _ in delta.added) == [(0, 0), (1, 0)] and not delta.newly_corrupt
        want = np.concatenate([file_xyz(mixed_fields / "1.0_1.0.pcd"), file_xyz(mixed_fields / "3.0_1.0.pcd")])
        assert store.merged().tobytes() == want.tobytes() and store.dtype == XYZ_DTYPE
        assert sorted(len(p) for p in store.point_arrays()) == [3, 5]
    finally:
        store.close()


def test_directory_errors_name_the_path(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        open_tile_directory(tmp_path / "nope", S)
    with pytest.raises(UserError, match="holds no tile files"):
        open_tile_directory(tmp_path, S)
    (tmp_path / "map.pcd").write_text("x")
    with pytest.raises(UserError, match=r"map\.pcd"):
        open_tile_directory(tmp_path, S)
    with pytest.raises(UserError, match="grid size"):
        open_tile_directory(tmp_path, None)


def test_off_map_window_is_empty_and_recovers(holey_map):
    store = TileStore(open_tile_directory(holey_map, S), prefetch=False)
    try:
        home = compute_window(1.0, 1.0, None, S, 2, 0)
        n_home = len(store.update(home).added)
        away = store.update(compute_window(1e6, -1e6, None, S, 2, 0))
        assert len(away.removed) == n_home and not away.added and store.merged().size == 0
        assert len(store.update(home).added) == n_home
    finally:
        store.close()


@pytest.fixture(scope="module")
def tiled_by_tiler(tmp_path_factory):
    """A map cut by the real tiler (index.json present)."""
    from fixtures.synthetic_tiles import POINT_DTYPE

    from grid_puzzle_localization.pcd import write_pcd
    from grid_puzzle_localization.tiling import TileConfig, tile_map

    root = tmp_path_factory.mktemp("tiler")
    rng = np.random.default_rng(11)
    pts = np.zeros(4000, dtype=POINT_DTYPE)
    pts["x"] = rng.uniform(-15.0, 9.0, len(pts))
    pts["y"] = rng.uniform(-5.0, 13.0, len(pts))
    write_pcd(root / "map.pcd", pts)
    tile_map([root / "map.pcd"], root / "tiles", TileConfig(grid_size=0.5, progress=False))
    return root / "tiles"


def test_index_gives_the_same_tiles_as_the_tiler_loader_and_the_listing(tiled_by_tiler):
    from grid_puzzle_localization.tiling import load_tile_index

    d = open_tile_directory(tiled_by_tiler)
    assert d.source == "index" and d.grid_size == 0.5
    reference = load_tile_index(tiled_by_tiler)
    assert {tuple(k) for k in d.keys.tolist()} == {t.key for t in reference.tiles}
    everything = compute_window(0.0, 0.0, None, 0.5, 100, 0)
    assert {tuple(k) for k in d.keys.tolist()} == brute_force_window_files(tiled_by_tiler, everything.bounds, 0.5)
    assert open_tile_directory(tiled_by_tiler, 0.5).source == "index"
    with pytest.raises(UserError, match="disagrees"):
        open_tile_directory(tiled_by_tiler, 2.0)


@pytest.mark.parametrize("chunk_bytes", [7, 64, 301, 4096, 1 << 20])
def test_streamed_index_keys_match_the_tiler_loader_across_chunk_boundaries(tiled_by_tiler, chunk_bytes):
    from grid_puzzle_localization.tiles.directory import read_index_keys
    from grid_puzzle_localization.tiling import load_tile_index

    s, keys = read_index_keys(tiled_by_tiler / "index.json", chunk_bytes)
    reference = load_tile_index(tiled_by_tiler)
    assert s == reference.grid_size
    assert keys.tolist() == sorted(list(t.key) for t in reference.tiles)


def test_index_of_another_format_is_refused(tmp_path):
    write_tiles(tmp_path, [(0, 0)], S, count=2)
    (tmp_path / "index.json").write_text('{"format": "other", "version": 1, "grid_size": 2.0, "tiles": []}')
    with pytest.raises(UserError, match="not a version 1 grid_puzzle_tiles index"):
        open_tile_directory(tmp_path)


def test_store_serves_tiler_output(tiled_by_tiler):
    store = TileStore(open_tile_directory(tiled_by_tiler), prefetch=False)
    try:
        window = compute_window(-3.0, 4.0, math.radians(300), 0.5, 3, 4)
        store.update(window)
        truth = brute_force_window_files(tiled_by_tiler, window.bounds, 0.5)
        assert {k for k, _ in store.loaded()} == truth and truth
        merged = store.merged()
        i = np.floor(merged["x"].astype(np.float64) / 0.5)
        assert i.min() >= window.i_min and i.max() <= window.i_max
    finally:
        store.close()


def test_broken_index_is_a_user_error(tmp_path):
    write_tiles(tmp_path, [(0, 0)], S, count=2)
    (tmp_path / "index.json").write_text("{not json")
    with pytest.raises(UserError, match="index"):
        open_tile_directory(tmp_path)


def test_turn_into_a_neighbouring_sector_is_served_from_the_prefetch_cache(holey_map):
    store = TileStore(open_tile_directory(holey_map, S), cache_mb=8.0)
    tracker = WindowTracker(WindowConfig(n=2, k=3), S)
    try:
        for x in (1.2, 2.7, 4.2, 5.7):  # east along y = 0.1
            store.update(tracker.update(PoseSample(x, 0.1)), tracker.predicted_windows())
            assert store.wait_prefetch_idle(timeout=30.0)
        # Turn to 45 deg: (6.76, 1.16) lies in the tile the prediction (7.22, 0.1) lies in.
        turned = tracker.update(PoseSample(5.7 + 1.5 * math.cos(math.pi / 4), 0.1 + 1.5 * math.sin(math.pi / 4)))
        assert turned.sector == 1
        delta = store.update(turned, tracker.predicted_windows())
        assert delta.added and delta.misses == 0
    finally:
        store.close()


def test_auto_cache_is_bounded_by_a_fraction_of_the_loaded_window(tmp_path):
    from grid_puzzle_localization.provider.tile_store import AUTO_CACHE_FRACTION, AUTO_CACHE_MIN_BYTES

    write_tiles(tmp_path, [(i, j) for i in range(30) for j in range(10)], S, count=8000)  # 96 kB of x y z
    store = TileStore(open_tile_directory(tmp_path, S))
    tracker = WindowTracker(WindowConfig(n=4, k=4), S)  # 9 x 13 tiles, 11 MB
    fullest, fraction_binds = 0.0, False
    try:
        for step in range(40):
            store.update(tracker.update(PoseSample(1.0 + 1.5 * step, 9.0)), tracker.predicted_windows())
            store.wait_prefetch_idle(timeout=30.0)
            stats = store.stats()
            limit = max(stats.bytes * AUTO_CACHE_FRACTION, AUTO_CACHE_MIN_BYTES)
            assert stats.cache_bytes <= limit
            fullest = max(fullest, stats.cache_bytes / limit)
            fraction_binds = fraction_binds or stats.bytes * AUTO_CACHE_FRACTION > AUTO_CACHE_MIN_BYTES
        assert fraction_binds and fullest > 0.8  # more tiles were read ahead and left behind than fit
    finally:
        store.close()
