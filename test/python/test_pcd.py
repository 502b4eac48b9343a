"""PCD I/O: round trips of every encoding with mixed field types, PCL as an independent reader, and
each kind of bad input producing its PcdError."""

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd import (
    ENCODINGS,
    PcdStreamWriter,
    iter_pcd_chunks,
    read_pcd,
    read_pcd_header,
    write_pcd,
    xyz_array,
)

MIXED = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("intensity", "<f4"),
        ("ring", "<u2"),
        ("time", "<f8"),
        ("rgb", "<f4"),
        ("normal", "<f4", (3,)),
        ("label", "<i1"),
        ("stamp", "<u8"),
    ]
)


def random_cloud(n: int, seed: int = 0) -> np.ndarray:
    """Finite xyz; every other field filled with random bits (so NaN patterns, extremes and packed
    opaque colours, which are NaN as floats, all occur)."""
    rng = np.random.default_rng(seed)
    cloud = np.frombuffer(rng.bytes(n * MIXED.itemsize), dtype=MIXED).copy()
    cloud["x"] = rng.uniform(-1e3, 1e3, n)
    cloud["y"] = rng.uniform(-1e3, 1e3, n)
    cloud["z"] = rng.normal(0.0, 10.0, n)
    return cloud


def assert_same(a: np.ndarray, b: np.ndarray, bitwise: bool) -> None:
    assert a.dtype == b.dtype and len(a) == len(b)
    if bitwise:
        assert a.tobytes() == b.tobytes()
        return
    for name in a.dtype.names:
        if a.dtype[name].base.kind == "f" and name != "rgb":
            np.testing.assert_array_equal(a[name], b[name])  # NaN == NaN here; payloads may differ
        else:
            assert a[name].tobytes() == b[name].tobytes(), name


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_keeps_fields_types_and_bits(tmp_path, encoding):
    cloud = random_cloud(3000)
    path = tmp_path / f"{encoding}.pcd"
    write_pcd(path, cloud, encoding)
    back = read_pcd(path)
    assert back.header.data == encoding
    assert back.header.fields == MIXED.names
    assert back.header.counts == (1, 1, 1, 1, 1, 1, 1, 3, 1, 1)
    assert back.nonfinite_dropped == 0
    assert_same(back.points, cloud, bitwise=encoding != "ascii")


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_empty_cloud_round_trips(tmp_path, encoding):
    path = tmp_path / "empty.pcd"
    write_pcd(path, np.empty(0, dtype=MIXED), encoding)
    back = read_pcd(path)
    assert len(back.points) == 0 and back.points.dtype == MIXED


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_nonfinite_xyz_dropped_and_counted(tmp_path, encoding):
    cloud = random_cloud(500, seed=1)
    bad = np.zeros(len(cloud), dtype=bool)
    bad[[3, 10, 11, 400]] = True
    cloud["x"][3], cloud["y"][10], cloud["z"][11], cloud["x"][400] = np.nan, np.inf, -np.inf, np.nan
    path = tmp_path / "nan.pcd"
    write_pcd(path, cloud, encoding)
    back = read_pcd(path)
    assert back.nonfinite_dropped == 4
    assert_same(back.points, cloud[~bad], bitwise=encoding != "ascii")


def test_huge_finite_coordinates_are_kept(tmp_path):
    """Coordinates whose sum overflows to inf are still finite points (the all-finite shortcut sums)."""
    cloud = np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    cloud["x"] = [3e38, 3e38, -3e38, 1.0]
    cloud["z"][3] = np.nan
    path = tmp_path / "huge.pcd"
    write_pcd(path, cloud)
    back = read_pcd(path)
    assert back.nonfinite_dropped == 1 and back.points.tobytes() == cloud[:3].tobytes()


def test_chunks_stream_in_order_and_count_drops(tmp_path):
    cloud = random_cloud(10_007, seed=2)
    cloud["z"][::1000] = np.nan
    path = tmp_path / "c.pcd"
    write_pcd(path, cloud)
    chunks = iter_pcd_chunks(path, chunk_points=1000)
    parts = list(chunks)
    assert all(len(p) <= 1000 for p in parts) and len(parts) == 11
    assert chunks.nonfinite_dropped == 11 and chunks.points_kept == 10_007 - 11
    assert np.concatenate(parts).tobytes() == cloud[np.isfinite(cloud["z"])].tobytes()


def test_stream_writer_fixes_header_and_is_atomic(tmp_path):
    cloud = random_cloud(2500, seed=3)
    path = tmp_path / "s.pcd"
    with PcdStreamWriter(path, MIXED) as w:
        for start in range(0, len(cloud), 1000):
            w.append(cloud[start : start + 1000])
        assert not path.exists()
    header = read_pcd_header(path)
    assert (header.points, header.width, header.height) == (2500, 2500, 1)
    assert read_pcd(path).points.tobytes() == cloud.tobytes()
    with pytest.raises(RuntimeError), PcdStreamWriter(tmp_path / "fail.pcd", MIXED) as w:
        w.append(cloud)
        raise RuntimeError("boom")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.pcd"]


def test_xyz_array_is_float64_columns():
    cloud = random_cloud(10)
    xyz = xyz_array(cloud)
    assert xyz.dtype == np.float64 and xyz.shape == (10, 3)
    np.testing.assert_array_equal(xyz[:, 2], cloud["z"].astype(np.float64))


# ---- real files and padded files, with PCL as the reference reader ----

needs_pcl = pytest.mark.skipif(shutil.which("pcl_convert_pcd_ascii_binary") is None, reason="pcl-tools not installed")


def read_with_pcl(path: Path, tmp_path: Path) -> np.ndarray:
    """The points PCL reads from ``path``, re-encoded by PCL as a plain binary file (POINTS records, no
    padding), finite x, y, z only as read_pcd returns them."""
    out = tmp_path / f"pcl_{path.parent.name}_{path.name}"
    subprocess.run(["pcl_convert_pcd_ascii_binary", str(path), str(out), "1"], check=True, capture_output=True)
    if read_pcd_header(path).points == 0:  # PCL reads no points and writes no file
        return np.empty(0, dtype=read_pcd_header(path).dtype)
    return read_pcd(out).points


def assert_reads_like_pcl(path: Path, tmp_path: Path) -> None:
    ours = read_pcd(path).points
    theirs = read_with_pcl(path, tmp_path)
    assert ours.dtype == theirs.dtype, path
    assert ours.tobytes() == theirs.tobytes(), path


def padded_copy(path: Path, fewer: int, out: Path) -> Path:
    """``path`` with WIDTH and POINTS lowered by ``fewer``: its data section then holds ``fewer`` more
    records than the header declares, like the zero-padded files some recorders write."""
    header = read_pcd_header(path)
    raw = path.read_bytes()
    head = raw[: header.header_bytes].decode()
    for key in ("WIDTH", "POINTS"):
        head = head.replace(f"\n{key} {header.points}\n", f"\n{key} {header.points - fewer}\n")
    out.write_bytes(head.encode() + raw[header.header_bytes :])
    return out


COMMITTED = sorted(Path(__file__).resolve().parents[1].joinpath("data").rglob("*.pcd"))


@needs_pcl
@pytest.mark.parametrize("path", COMMITTED, ids=lambda p: p.name)
def test_committed_real_files_read_like_pcl(path, tmp_path):
    assert_reads_like_pcl(path, tmp_path)


@needs_pcl
def test_shared_real_files_read_like_pcl(shared_real_data, tmp_path):
    # PCL is run once per file (about 40 ms), so the 1,500 campus tiles and the 330 MulRan scans are sampled
    # here; the C++ reader's gtest compares every file in process.
    files = sorted(shared_real_data.rglob("*.pcd"))
    many = ("nova_utd_tiles", "Scans")
    sample = [f for k, f in enumerate(files) if not any(d in f.parts for d in many) or k % 20 == 0]
    assert len(sample) > 50
    for path in sample:
        assert_reads_like_pcl(path, tmp_path)


@needs_pcl
def test_padded_real_binary_file_reads_points_records_like_pcl(real_data, tmp_path):
    real = real_data / "hdl32_pair" / "251370668.pcd"
    padded = padded_copy(real, 327, tmp_path / "padded.pcd")
    assert_reads_like_pcl(padded, tmp_path)
    whole, head = read_pcd(real).points, read_pcd(padded).points
    assert read_pcd_header(padded).points == 69_088 - 327
    assert head.tobytes() == whole[: len(head)].tobytes()
    assert len(head) < len(whole)


@needs_pcl
def test_padded_ascii_file_reads_points_lines_like_pcl(tmp_path):
    path = write_text(tmp_path / "a.pcd", HEADER.format(n=2, enc="ascii") + "1 2 3\n4 5 6\n7 8 9\n0 0 0\n")
    assert_reads_like_pcl(path, tmp_path)
    np.testing.assert_array_equal(xyz_array(read_pcd(path).points), [[1, 2, 3], [4, 5, 6]])


def test_real_binary_compressed_utm_decodes_known_count(real_data):
    cloud = read_pcd(real_data / "isprs_terrain_utm" / "samp11-utm.pcd")
    assert cloud.header.data == "binary_compressed" and len(cloud.points) == 38010


@pytest.mark.skipif(shutil.which("pcl_convert_pcd_ascii_binary") is None, reason="pcl-tools not installed")
@pytest.mark.parametrize(
    ("ours", "theirs"),
    [("ascii", "binary_compressed"), ("binary_compressed", "ascii"), ("binary", "binary_compressed")],
)
def test_pcl_reads_what_we_write(tmp_path, ours, theirs):
    # PCL, the reference implementation, re-encodes our file; we must read back the same points.
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("t", "<f8")])
    rng = np.random.default_rng(4)
    cloud = np.empty(1000, dtype)
    for name in ("x", "y", "z", "intensity"):
        cloud[name] = rng.uniform(-500.0, 500.0, len(cloud))
    cloud["ring"] = rng.integers(0, 128, len(cloud))
    cloud["t"] = rng.uniform(0.0, 0.1, len(cloud))
    src, dst = tmp_path / "ours.pcd", tmp_path / "pcl.pcd"
    write_pcd(src, cloud, ours)
    code = str(ENCODINGS.index(theirs))
    subprocess.run(["pcl_convert_pcd_ascii_binary", str(src), str(dst), code, "17"], check=True, capture_output=True)
    back = read_pcd(dst)
    assert back.header.data == theirs and back.header.fields == dtype.names
    assert_same(back.points, cloud, bitwise=False)


# ---- bad input: each case names the file and the problem ----


def write_text(path: Path, text: str, data: bytes = b"") -> Path:
    path.write_bytes(text.encode() + data)
    return path


HEADER = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA {enc}\n"


def test_missing_file(tmp_path):
    with pytest.raises(PcdError, match=r"nope\.pcd: no such file"):
        read_pcd(tmp_path / "nope.pcd")


def test_truncated_binary(tmp_path):
    path = write_text(tmp_path / "t.pcd", HEADER.format(n=10, enc="binary"), bytes(12 * 9 + 5))
    with pytest.raises(PcdError, match=r"t\.pcd: truncated"):
        read_pcd(path)


def test_truncated_ascii_and_ragged_lines(tmp_path):
    short = write_text(tmp_path / "short.pcd", HEADER.format(n=3, enc="ascii") + "1 2 3\n4 5 6\n")
    with pytest.raises(PcdError, match=r"short\.pcd: truncated"):
        read_pcd(short)
    ragged = write_text(tmp_path / "ragged.pcd", HEADER.format(n=2, enc="ascii") + "1 2 3\n4 5\n")
    with pytest.raises(PcdError, match=r"ragged\.pcd: line 11 has 2 values"):
        read_pcd(ragged)


def test_compressed_sizes_beyond_the_file_are_refused_before_allocating(tmp_path):
    # 4 GB claimed from 16 LZF bytes: refused from the sizes alone (LZF expands at most 88 times).
    sizes = np.array([16, 0xFFFFFFF0], dtype="<u4").tobytes()
    huge = write_text(tmp_path / "huge.pcd", HEADER.format(n=357913940, enc="binary_compressed"), sizes + bytes(16))
    with pytest.raises(PcdError, match=r"huge\.pcd: corrupt binary_compressed sizes"):
        read_pcd(huge)
    overclaim = write_text(tmp_path / "over.pcd", HEADER.format(n=10, enc="binary_compressed"), sizes[:4] + bytes(4))
    with pytest.raises(PcdError, match=r"over\.pcd: truncated: 16 compressed bytes declared, 0 present"):
        read_pcd(overclaim)


def test_compressed_points_disagreeing_and_truncated(tmp_path):
    path = tmp_path / "c.pcd"
    write_pcd(path, random_cloud(100)[["x", "y", "z"]], "binary_compressed")
    data = path.read_bytes()
    wrong = write_text(
        tmp_path / "wrong.pcd", "", data.replace(b"POINTS 100", b"POINTS 99 ").replace(b"WIDTH 100", b"WIDTH 99 ")
    )
    with pytest.raises(PcdError, match=r"wrong\.pcd: POINTS 99 disagrees"):
        read_pcd(wrong)
    cut = write_text(tmp_path / "cut.pcd", "", data[:-10])
    with pytest.raises(PcdError, match=r"cut\.pcd: truncated"):
        read_pcd(cut)


def test_unknown_encoding(tmp_path):
    path = write_text(tmp_path / "e.pcd", HEADER.format(n=0, enc="binary_zstd"))
    with pytest.raises(PcdError, match=r"e\.pcd: unknown DATA encoding 'binary_zstd'"):
        read_pcd_header(path)
    with pytest.raises(PcdError, match="unknown PCD encoding 'lz4'"):
        write_pcd(tmp_path / "w.pcd", random_cloud(2), "lz4")


def test_missing_xyz_field(tmp_path):
    text = HEADER.format(n=0, enc="binary").replace("FIELDS x y z", "FIELDS x y intensity")
    path = write_text(tmp_path / "noz.pcd", text)
    with pytest.raises(PcdError, match=r"noz\.pcd: no 'z' field"):
        read_pcd(path)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("SIZE 4 4", "SIZE has 2 entries but FIELDS names 3"),
        ("TYPE F F X", "unsupported TYPE X"),
        ("WIDTH ten", "bad header line 'WIDTH ten'"),
        ("WIDTH 7", "WIDTH 7 x HEIGHT 1 disagrees with POINTS 0"),
        ("FOO 1", "bad header line 'FOO 1'"),
    ],
)
def test_bad_header_lines(tmp_path, line, message):
    key = line.split()[0]
    lines = [ln for ln in HEADER.format(n=0, enc="binary").splitlines() if not ln.startswith(key)]
    path = write_text(tmp_path / "h.pcd", "\n".join([*lines[:-1], line, lines[-1]]) + "\n")
    with pytest.raises(PcdError, match=rf"h\.pcd: .*{message}"):
        read_pcd_header(path)


def test_not_a_pcd(tmp_path):
    path = write_text(tmp_path / "x.pcd", "hello")
    with pytest.raises(PcdError, match=r"x\.pcd: header has no DATA line"):
        read_pcd_header(path)
