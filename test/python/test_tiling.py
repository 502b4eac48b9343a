"""The tiler against brute force: every finite point in exactly one tile, bit for bit and in input
order, the tile being floor(x / s), floor(y / s) computed per point in plain Python."""

from __future__ import annotations

import hashlib
import json
import math
import os
import resource
import shutil
import signal
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from grid_puzzle_localization.cli import main
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import PcdHeader, read_pcd, read_pcd_header, write_pcd
from grid_puzzle_localization.pcd.header import parse_header
from grid_puzzle_localization.tiles.grid import tile_filename
from grid_puzzle_localization.tiling import (
    AUTOWARE_METADATA_FILE,
    TileConfig,
    load_tile_index,
    tile_map,
    verify_tiles,
)
from grid_puzzle_localization.tiling.buffer import TileSet, write_all
from grid_puzzle_localization.tiling.grouping import GROUP_DTYPE, key_positions
from grid_puzzle_localization.tiling.index import JSON_BATCH, TileEntry, TileIndex, TileTable, write_index
from grid_puzzle_localization.tiling.tile_files import TileFileWriter, TileHeader
from grid_puzzle_localization.tiling.tiler import MIN_TILES_TO_FORK
from grid_puzzle_localization.util.iteration import zip_equal

FIELDS = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<u1"), ("t", "<f8"), ("n", "<f4", (2,))])


def random_cloud(n: int, s: float, seed: int) -> np.ndarray:
    """Points around the origin (negative and positive), a tenth of them exactly on cell boundaries."""
    rng = np.random.default_rng(seed)
    cloud = np.frombuffer(rng.bytes(n * FIELDS.itemsize), dtype=FIELDS).copy()
    cloud["x"] = rng.uniform(-10 * s, 10 * s, n)
    cloud["y"] = rng.uniform(-7 * s, 13 * s, n)
    cloud["z"] = rng.normal(0.0, 5.0, n)
    edge = rng.random(n) < 0.1
    cloud["x"][edge] = rng.integers(-10, 10, edge.sum()) * np.float32(s)
    cloud["y"][edge[::-1]] = rng.integers(-7, 13, edge.sum()) * np.float32(s)
    return cloud


def records_of(cloud: np.ndarray) -> list[bytes]:
    raw = cloud.tobytes()
    size = cloud.dtype.itemsize
    return [raw[k : k + size] for k in range(0, len(raw), size)]


def expected_tiles(cloud: np.ndarray, s: float) -> dict[tuple[int, int], bytes]:
    tiles: dict[tuple[int, int], list[bytes]] = defaultdict(list)
    for record, x, y in zip_equal(records_of(cloud), cloud["x"].tolist(), cloud["y"].tolist()):
        tiles[(math.floor(x / s), math.floor(y / s))].append(record)
    return {key: b"".join(records) for key, records in tiles.items()}


def tiled_contents(out_dir: Path) -> dict[tuple[int, int], bytes]:
    index = load_tile_index(out_dir)
    return {entry.key: read_pcd(index.path(entry)).points.tobytes() for entry in index.tiles}


@pytest.mark.parametrize(("s", "memory_mb"), [(2.0, 64.0), (0.3, 1.0), (5.0, 1.0)])
def test_every_point_in_exactly_its_tile_bit_for_bit(tmp_path, s, memory_mb):
    # memory_mb 1 forces many spills to disk; 64 keeps everything in memory.
    cloud = random_cloud(60_000, s, seed=int(s * 10))
    src = tmp_path / "map.pcd"
    write_pcd(src, cloud)
    result = tile_map([src], tmp_path / "tiles", TileConfig(grid_size=s, memory_mb=memory_mb))
    assert (result.spills > 0) == (memory_mb == 1.0)
    expected = expected_tiles(cloud, s)
    assert tiled_contents(tmp_path / "tiles") == expected
    index = load_tile_index(tmp_path / "tiles")
    assert index.points == len(cloud) and index.nonfinite_dropped == 0
    for entry in index.tiles:
        assert entry.file == tile_filename(*entry.key, s)
        points = read_pcd(index.path(entry)).points
        assert entry.points == len(points)
        assert entry.bounds["min"] == [float(points[c].min()) for c in "xyz"]
        assert entry.bounds["max"] == [float(points[c].max()) for c in "xyz"]
        assert entry.bytes == index.path(entry).stat().st_size
        assert entry.sha256 == hashlib.sha256(index.path(entry).read_bytes()).hexdigest()
    assert sorted(p.name for p in (tmp_path / "tiles").iterdir()) == sorted(
        [e.file for e in index.tiles] + ["index.json", AUTOWARE_METADATA_FILE]
    )
    assert verify_tiles(tmp_path / "tiles", [src]).ok


def test_nonfinite_points_dropped_and_counted(tmp_path):
    cloud = random_cloud(1000, 1.0, seed=7)
    cloud["x"][[1, 5]] = np.nan
    cloud["z"][9] = np.inf
    src = tmp_path / "map.pcd"
    write_pcd(src, cloud)
    tile_map([src], tmp_path / "tiles", TileConfig(grid_size=1.0))
    index = load_tile_index(tmp_path / "tiles")
    assert index.nonfinite_dropped == 3 and index.points == 997
    finite = np.isfinite(cloud["x"]) & np.isfinite(cloud["z"])
    assert tiled_contents(tmp_path / "tiles") == expected_tiles(cloud[finite], 1.0)


def test_autoware_metadata_lists_each_tile_corner(tmp_path):
    s = 2.5
    cloud = random_cloud(2000, s, seed=3)
    src = tmp_path / "map.pcd"
    write_pcd(src, cloud)
    tile_map([src], tmp_path / "tiles", TileConfig(grid_size=s))
    meta = yaml.safe_load((tmp_path / "tiles" / AUTOWARE_METADATA_FILE).read_text())
    keys = expected_tiles(cloud, s).keys()
    assert meta.pop("x_resolution") == s and meta.pop("y_resolution") == s
    assert meta == {tile_filename(i, j, s): [i * s, j * s] for i, j in keys}
    for name, (min_x, min_y) in meta.items():
        points = read_pcd(tmp_path / "tiles" / name).points
        assert (points["x"] >= min_x).all() and (points["x"] < min_x + s).all()
        assert (points["y"] >= min_y).all() and (points["y"] < min_y + s).all()


def test_utm_terrain_binary_compressed_pieces(real_data, tmp_path):
    # Two real airborne scans (UTM 32U, y ~ 5.4e6 m, binary_compressed) as pieces of one map.
    pieces = [real_data / "isprs_terrain_utm" / name for name in ("samp11-utm.pcd", "CSite1_red2-utm.pcd")]
    s = 20.0
    tile_map(pieces, tmp_path / "tiles", TileConfig(grid_size=s, memory_mb=2.0))
    cloud = np.concatenate([read_pcd(p).points for p in pieces])
    assert tiled_contents(tmp_path / "tiles") == expected_tiles(cloud, s)
    index = load_tile_index(tmp_path / "tiles")
    assert min(e.key[1] for e in index.tiles) > 5.3e6 / s  # UTM northings kept exact
    assert verify_tiles(tmp_path / "tiles", pieces).ok


def test_inputs_with_different_fields_are_refused(tmp_path, real_data):
    other = tmp_path / "other.pcd"
    write_pcd(other, random_cloud(10, 1.0, seed=1))
    with pytest.raises(UserError, match=r"other\.pcd: fields .* differ from .*samp11-utm\.pcd"):
        tile_map([real_data / "isprs_terrain_utm" / "samp11-utm.pcd", other], tmp_path / "t", TileConfig(2.0))
    assert not (tmp_path / "t").exists()


def test_failure_leaves_no_output_behind(tmp_path):
    good, bad = tmp_path / "good.pcd", tmp_path / "bad.pcd"
    write_pcd(good, random_cloud(5000, 1.0, seed=2))
    write_pcd(bad, random_cloud(5000, 1.0, seed=3))
    bad.write_bytes(bad.read_bytes()[:-100])  # truncated: detected only while streaming
    with pytest.raises(UserError, match=r"bad\.pcd: truncated"):
        tile_map([good, bad], tmp_path / "out", TileConfig(grid_size=1.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.pcd", "good.pcd"]


# ---- the real campus map: merged into one global PCD, re-cut, conserved ----


@pytest.fixture(scope="module")
def campus_map(shared_real_data, tmp_path_factory) -> Path:
    from grid_puzzle_localization.pcd import merge_pcds

    path = tmp_path_factory.mktemp("campus") / "campus.pcd"
    merge_pcds(sorted((shared_real_data / "nova_utd_tiles" / "tiles").glob("*.pcd")), path)
    return path


@pytest.mark.parametrize("s", [2.0, 20.0])
def test_real_campus_map_recut_conserves_points(campus_map, tmp_path, s):
    out = tmp_path / f"s{s:g}"
    result = tile_map([campus_map], out, TileConfig(grid_size=s, memory_mb=32.0))
    assert result.spills > 0  # 60 MB of points through an 18 MB buffer
    assert result.index.points == 5_052_377  # as documented for the data set
    report = verify_tiles(out, [campus_map])
    assert report.ok, report.problems
    assert report.points_in == report.points_tiles == 5_052_377
    assert report.bytes_tiles_data == report.bytes_in_data == 5_052_377 * 12
    assert report.bytes_tiles_total == report.bytes_tiles_data + report.bytes_tiles_headers
    if s == 20.0:  # brute force on the whole set (cheap with few tiles): sorted records are equal
        tiles = np.concatenate([read_pcd(result.index.path(e)).points for e in result.index.tiles])
        cloud = read_pcd(campus_map).points
        order_t = np.lexsort((tiles["z"], tiles["y"], tiles["x"]))
        order_c = np.lexsort((cloud["z"], cloud["y"], cloud["x"]))
        assert tiles[order_t].tobytes() == cloud[order_c].tobytes()


# ---- command line ----


def run_gpm(*args: str) -> subprocess.CompletedProcess:
    code = "import sys; from grid_puzzle_localization.cli import main; sys.exit(main())"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)


def test_cli_tiles_verifies_and_detects_tampering(tmp_path):
    src = tmp_path / "map.pcd"
    write_pcd(src, random_cloud(3000, 1.0, seed=5))
    out = tmp_path / "tiles"
    assert main(["tile", "--grid-size", "1", str(src), "-o", str(out)]) == 0
    done = run_gpm("tile", "--verify", str(out), str(src))
    assert done.returncode == 0 and "conservation: OK" in done.stdout
    index = json.loads((out / "index.json").read_text())
    victim = out / index["tiles"][0]["file"]
    cloud = read_pcd(victim).points
    write_pcd(victim, cloud[:-1])
    done = run_gpm("tile", "--verify", str(out), str(src))
    assert done.returncode == 1 and "conservation: FAILED" in done.stdout


def test_cli_refuses_non_empty_output_without_force(tmp_path):
    src = tmp_path / "map.pcd"
    write_pcd(src, random_cloud(100, 1.0, seed=6))
    out = tmp_path / "tiles"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    done = run_gpm("tile", "--grid-size", "1", str(src), "-o", str(out))
    assert done.returncode == 2
    assert "tiles: output directory is not empty" in done.stderr and "--force" in done.stderr
    assert (out / "keep.txt").read_text() == "mine"
    assert run_gpm("tile", "--grid-size", "1", str(src), "-o", str(out), "--force").returncode == 0
    assert not (out / "keep.txt").exists() and (out / "index.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pcd", "tiles"]


def test_cli_missing_input_and_bad_grid_size(tmp_path):
    done = run_gpm("tile", "--grid-size", "1", str(tmp_path / "nope.pcd"), "-o", str(tmp_path / "t"))
    assert done.returncode == 2 and "nope.pcd: no such file" in done.stderr
    src = tmp_path / "map.pcd"
    write_pcd(src, random_cloud(10, 1.0, seed=6))
    done = run_gpm("tile", "--grid-size", "-2", str(src), "-o", str(tmp_path / "t"))
    assert done.returncode == 2 and "grid size must be a positive" in done.stderr
    assert not (tmp_path / "t").exists()


def test_verify_reports_points_moved_between_tiles(tmp_path):
    src = tmp_path / "map.pcd"
    write_pcd(src, random_cloud(3000, 1.0, seed=8))
    out = tmp_path / "tiles"
    tile_map([src], out, TileConfig(grid_size=1.0))
    index = load_tile_index(out)
    a, b = (index.path(e) for e in index.tiles[:2])
    pa, pb = read_pcd(a).points, read_pcd(b).points
    pa[0], pb[0] = pb[0].copy(), pa[0].copy()  # same records and counts overall, two in the wrong cell
    write_pcd(a, pa)
    write_pcd(b, pb)
    report = verify_tiles(out, [src])
    assert report.misplaced_points == 2 and report.checksum_in == report.checksum_tiles
    assert not report.ok and "2 tile points lie outside their tile's cell" in report.problems


@pytest.mark.skipif(shutil.which("pcl_convert_pcd_ascii_binary") is None, reason="pcl-tools not installed")
def test_pcl_reads_the_tiles(tmp_path):
    src = tmp_path / "map.pcd"
    write_pcd(src, random_cloud(2000, 4.0, seed=9))
    tile_map([src], tmp_path / "tiles", TileConfig(grid_size=4.0))
    index = load_tile_index(tmp_path / "tiles")
    for entry in index.tiles[:5]:
        converted = tmp_path / "pcl.pcd"
        subprocess.run(
            ["pcl_convert_pcd_ascii_binary", str(index.path(entry)), str(converted), "2"],
            check=True,
            capture_output=True,
        )
        assert read_pcd(converted).points.tobytes() == read_pcd(index.path(entry)).points.tobytes()


# ---- the write path: many tiles, parallel writers, failure mid-write, the index text ----


def wide_cloud(n: int, s: float, cells: int, seed: int) -> np.ndarray:
    """A random cloud over cells x cells tiles (so more than MIN_TILES_TO_FORK of them), around the origin."""
    cloud = random_cloud(n, s, seed)
    rng = np.random.default_rng(seed + 1)
    cloud["x"] = rng.uniform(-cells / 2 * s, cells / 2 * s, n)
    cloud["y"] = rng.uniform(-cells / 3 * s, 2 * cells / 3 * s, n)
    return cloud


@pytest.mark.parametrize(("jobs", "memory_mb"), [(2, 64.0), (2, 1.0), (1, 64.0), (3, 1.0)])
def test_many_tiles_with_parallel_writers_bit_for_bit(tmp_path, jobs, memory_mb):
    s = 0.5
    cloud = wide_cloud(40_000, s, cells=60, seed=11)
    src = tmp_path / "map.pcd"
    write_pcd(src, cloud)
    result = tile_map([src], tmp_path / "tiles", TileConfig(grid_size=s, memory_mb=memory_mb, jobs=jobs))
    assert len(result.index.tiles) >= MIN_TILES_TO_FORK  # so `jobs` writers really ran
    assert (result.spills > 0) == (memory_mb == 1.0)
    assert tiled_contents(tmp_path / "tiles") == expected_tiles(cloud, s)
    assert sorted(p.name for p in (tmp_path / "tiles").iterdir()) == sorted(
        [e.file for e in result.index.tiles] + ["index.json", AUTOWARE_METADATA_FILE]
    )
    # Each writer hashed its own batches into the shared table; the index names every file's digest.
    index = load_tile_index(tmp_path / "tiles")
    assert [e.sha256 for e in index.tiles] == [
        hashlib.sha256(index.path(e).read_bytes()).hexdigest() for e in index.tiles
    ]


@pytest.fixture
def file_size_limit():
    """Sets RLIMIT_FSIZE for this process and the writers it forks (writes past it fail with EFBIG, as
    on a full disk), and restores it afterwards."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # else the kernel kills the writer
    yield lambda limit: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    signal.signal(signal.SIGXFSZ, previous)


@pytest.mark.parametrize("jobs", [1, 2])
@pytest.mark.parametrize("existing", [False, True])
def test_failure_mid_write_leaves_nothing_behind(tmp_path, file_size_limit, jobs, existing):
    cloud = wide_cloud(20_000, 0.5, cells=60, seed=12)
    big = np.repeat(cloud[:1], 150_000)  # one tile of 4.35 MB, past the limit below; the others are small
    src = tmp_path / "map.pcd"
    write_pcd(src, np.concatenate([cloud, big]))
    out = tmp_path / "tiles"
    if existing:  # an earlier output that --force would replace: it must survive the failure intact
        out.mkdir()
        (out / "old.pcd").write_text("old tiles")
    file_size_limit(4 * 2**20)
    with pytest.raises(OSError, match="File too large" if jobs == 1 else "tile writer process failed"):
        tile_map([src], out, TileConfig(grid_size=0.5, jobs=jobs, force=True, progress=False))
    assert sorted(p.name for p in tmp_path.iterdir()) == (["map.pcd", "tiles"] if existing else ["map.pcd"])
    if existing:
        assert [p.name for p in out.iterdir()] == ["old.pcd"] and (out / "old.pcd").read_text() == "old tiles"


def test_tile_writer_error_names_the_file(tmp_path):
    out = tmp_path / "tiles"
    out.mkdir()
    writer = TileFileWriter(tiles_with_counts([3, 5]), TileHeader.like(fields_header(tmp_path)), out)
    (out / "b.pcd").write_text("taken")
    dir_fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
    try:
        with pytest.raises(FileExistsError) as error:
            writer.write(dir_fd, range(2), ["a.pcd", "b.pcd"])
    finally:
        os.close(dir_fd)
    assert error.value.filename == str(out / "b.pcd")
    assert (out / "b.pcd").read_text() == "taken" and (out / "a.pcd").stat().st_size > 0


def test_index_text_is_what_json_would_write(tmp_path):
    table = TileTable(
        i=[-3, 4],
        j=[2_812_345, -1],
        files=["-5.0_5624691.0.pcd", "9.0_-1.0.pcd"],
        points=[7, 1],
        bytes=[250, 180],
        lower=[[-5.999999523162842, 8.5], [5624690.5, -2.0], [-0.0, 3.0]],
        upper=[[-4.0, 8.5], [5624691.75, -2.0], [1e-300, 3.0]],
    )
    index = TileIndex(2.0, [{"name": "x", "size": 4, "type": "F", "count": 1}], 12, 8, 0, [], table)
    expected = [
        {
            "key": [-3, 2_812_345],
            "stem": "-5.0_5624691.0",
            "file": "-5.0_5624691.0.pcd",
            "center": [-5.0, 5624691.0],
            "points": 7,
            "bounds": {"min": [-5.999999523162842, 5624690.5, -0.0], "max": [-4.0, 5624691.75, 1e-300]},
            "bytes": 250,
            "data_bytes": 84,
        },
        {
            "key": [4, -1],
            "stem": "9.0_-1.0",
            "file": "9.0_-1.0.pcd",
            "center": [9.0, -1.0],
            "points": 1,
            "bounds": {"min": [8.5, -2.0, 3.0], "max": [8.5, -2.0, 3.0]},
            "bytes": 180,
            "data_bytes": 12,
        },
    ]
    assert b"".join(table.json_parts(2.0, 12)).decode() == json.dumps(expected, separators=(",", ":"))
    write_index(tmp_path, index)
    assert json.loads((tmp_path / "index.json").read_text())["tiles"] == expected
    loaded = load_tile_index(tmp_path)
    assert loaded.table == table
    as_entries = [
        TileEntry(**{**e, "key": tuple(e["key"]), "center": tuple(e["center"])})  # type: ignore[arg-type]
        for e in expected
    ]
    assert loaded.tiles == as_entries


def test_index_checksums_round_trip_and_a_partial_column_is_refused(tmp_path):
    digests = [hashlib.sha256(b"a").hexdigest(), hashlib.sha256(b"b").hexdigest()]
    table = TileTable(
        [0, 1], [0, 0], ["1.0_1.0.pcd", "3.0_1.0.pcd"], [1, 2], [200, 212], [[0.5, 2.5]] * 3, [[0.5, 2.5]] * 3
    )
    table = TileTable(**{**table.__dict__, "sha256": digests})
    write_index(tmp_path, TileIndex(2.0, [], 12, 3, 0, [], table))
    raw = json.loads((tmp_path / "index.json").read_text())
    assert [t["sha256"] for t in raw["tiles"]] == digests
    assert [e.sha256 for e in load_tile_index(tmp_path).tiles] == digests
    for bad, what in ((None, "some tiles have a sha256"), ("ABC", "not 64 lowercase hex")):
        broken = json.loads(json.dumps(raw))
        if bad is None:
            del broken["tiles"][1]["sha256"]
        else:
            broken["tiles"][1]["sha256"] = bad
        (tmp_path / "index.json").write_text(json.dumps(broken))
        with pytest.raises(UserError, match=what):
            load_tile_index(tmp_path)


@settings(max_examples=500, deadline=None)
@given(
    st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=6, max_size=6),
    st.integers(-(2**50), 2**50),
    st.floats(1e-3, 1e4),
)
def test_index_floats_are_written_as_python_repr(bounds, i, s):
    table = TileTable([i], [-i], ["a_b.pcd"], [3], [99], [[v] for v in bounds[:3]], [[v] for v in bounds[3:]])
    expected = {
        "key": [i, -i],
        "stem": "a_b",
        "file": "a_b.pcd",
        "center": [(i + 0.5) * s, (-i + 0.5) * s],
        "points": 3,
        "bounds": {"min": bounds[:3], "max": bounds[3:]},
        "bytes": 99,
        "data_bytes": 36,
    }
    assert b"".join(table.json_parts(s, 12)).decode() == json.dumps([expected], separators=(",", ":"))


@pytest.mark.parametrize("tiles", [0, 1, JSON_BATCH, 2 * JSON_BATCH + 5])
def test_index_text_in_parts_is_what_json_would_write(tiles):
    rng = np.random.default_rng(tiles)
    i, j = rng.integers(-(10**6), 10**6, tiles).tolist(), rng.integers(-(10**6), 10**6, tiles).tolist()
    table = TileTable(
        i=i,
        j=j,
        files=[tile_filename(a, b, 0.3) for a, b in zip_equal(i, j)],
        points=rng.integers(1, 10**6, tiles).tolist(),
        bytes=rng.integers(200, 10**7, tiles).tolist(),
        lower=rng.normal(0.0, 1e5, (3, tiles)).astype(np.float32).astype(float).tolist(),
        upper=rng.normal(0.0, 1e5, (3, tiles)).tolist(),
    )
    expected = [
        {
            "key": [a, b],
            "stem": f[: -len(".pcd")],
            "file": f,
            "center": [(a + 0.5) * 0.3, (b + 0.5) * 0.3],
            "points": n,
            "bounds": {"min": [x0, y0, z0], "max": [x1, y1, z1]},
            "bytes": size,
            "data_bytes": n * 16,
        }
        for a, b, f, n, size, x0, y0, z0, x1, y1, z1 in zip_equal(
            i, j, table.files, table.points, table.bytes, *table.lower, *table.upper
        )
    ]
    assert b"".join(table.json_parts(0.3, 16)).decode() == json.dumps(expected, separators=(",", ":"))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(-(2**62), 2**62), st.integers(-(2**62), 2**62)), min_size=1, max_size=60))
def test_key_positions_equal_a_dictionary_lookup(keys):
    distinct = sorted(set(keys))
    where = {key: t for t, key in enumerate(distinct)}
    si, sj = (np.array(column, dtype=np.int64) for column in zip_equal(*distinct))
    qi, qj = (np.array(column, dtype=np.int64) for column in zip_equal(*keys))
    assert key_positions(si, sj, qi, qj).tolist() == [where[key] for key in keys]


def test_gpm_tile_imports_no_other_command():
    code = (
        "import sys; from grid_puzzle_localization.cli import main\n"
        "try:\n    main(['tile', '--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('matplotlib', 'rospy', 'scipy', 'grid_puzzle_localization.sim') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert "--grid-size" in done.stdout


def test_write_all_finishes_a_partial_writev(tmp_path, monkeypatch):
    parts = [b"header\n", np.arange(10, dtype=np.uint8), b"", np.frombuffer(b"tail", dtype=np.uint8)]
    expected = b"".join(bytes(p) for p in parts)
    real_writev = os.writev
    monkeypatch.setattr(os, "writev", lambda fd, buffers: os.write(fd, bytes(buffers[0])[:5]))  # as a kernel may
    fd = os.open(tmp_path / "out", os.O_WRONLY | os.O_CREAT)
    write_all(fd, parts)
    os.close(fd)
    assert (tmp_path / "out").read_bytes() == expected
    monkeypatch.setattr(os, "writev", real_writev)
    fd = os.open(tmp_path / "out2", os.O_WRONLY | os.O_CREAT)
    write_all(fd, parts * 700)  # more buffers than one writev takes
    os.close(fd)
    assert (tmp_path / "out2").read_bytes() == expected * 700


def fields_header(directory: Path) -> PcdHeader:
    """The header of a PCD file with FIELDS."""
    path = directory / "fields.pcd"
    write_pcd(path, random_cloud(1, 1.0, seed=13))
    return read_pcd_header(path)


def tiles_with_counts(counts: list[int]) -> TileSet:
    """A TileSet whose tiles declare ``counts`` points but have no points buffered."""
    stats = np.zeros(len(counts), dtype=GROUP_DTYPE)
    stats["count"] = counts
    none = np.zeros(len(counts), dtype=np.int64)
    empty = np.zeros(0, dtype=np.int64)
    return TileSet(stats, [None] * len(counts), none, none, empty, empty, empty, [])


def test_tile_header_declares_n_points_and_knows_its_size(tmp_path):
    counts = [0, 1, 9, 10, 99, 100, 12_345, 10**12, 10**12 - 1]
    template = TileHeader.like(fields_header(tmp_path))
    out = tmp_path / "tiles"
    out.mkdir()
    writer = TileFileWriter(tiles_with_counts(counts), template, out)
    names = [f"{n}.pcd" for n in counts]
    dir_fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
    try:
        writer.write(dir_fd, range(len(counts)), names)
    finally:
        os.close(dir_fd)
    texts = [(out / name).read_bytes() for name in names]
    assert template.sizes(np.array(counts)).tolist() == [len(text) for text in texts]
    for n, text in zip_equal(counts, texts):
        parsed = parse_header(text, "tile")
        assert (parsed.points, parsed.width, parsed.height, parsed.data) == (n, n, 1, "binary")
        assert parsed.dtype == FIELDS and parsed.header_bytes == len(text)
