"""Grouping a chunk by tile (the C++ library behind tiling.grouping) against plain Python: each point's
tile floor(x / s), floor(y / s) from Python floats, a stable sort by tile, bounds from min and max."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiling.grouping import GROUP_DTYPE, group_chunk
from grid_puzzle_localization.util.iteration import zip_equal

COORDINATE_TYPES = ["<f4", "<f8", "<i2", "<u4", "<i8"]


def python_grouping(records: np.ndarray, s: float) -> tuple[bytes, list[tuple]]:
    """Sorted record bytes and (i, j, start, count, min, max) per tile, point by point."""
    size = records.dtype.itemsize
    raw = records.tobytes()
    keyed = [
        ((math.floor(float(r["x"]) / s), math.floor(float(r["y"]) / s)), k, tuple(float(r[a]) for a in "xyz"))
        for k, r in enumerate(records)
    ]
    keyed.sort(key=lambda item: item[0])  # stable: input order inside a tile
    tiles: list[tuple] = []
    for at, (key, _, xyz) in enumerate(keyed):
        if not tiles or tiles[-1][0] != key:
            tiles.append((key, at, []))
        tiles[-1][2].append(xyz)
    expected = [
        (i, j, at, len(xyz), [min(c) for c in zip_equal(*xyz)], [max(c) for c in zip_equal(*xyz)])
        for (i, j), at, xyz in tiles
    ]
    return b"".join(raw[k * size : (k + 1) * size] for _, k, _ in keyed), expected


@st.composite
def chunks(draw) -> np.ndarray:
    types = [draw(st.sampled_from(COORDINATE_TYPES)) for _ in "xyz"]
    dtype = np.dtype([("x", types[0]), ("y", types[1]), ("intensity", "<u1"), ("z", types[2])])
    extent = draw(st.sampled_from([1.0, 50.0, 1e4, 1e9, 1e15]))  # from one tile to a sparse spread
    n = draw(st.integers(1, 300))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    records = np.zeros(n, dtype=dtype)
    for axis in "xyz":
        kind = records.dtype[axis]
        if kind.kind == "f":
            values = rng.uniform(-extent, extent, n)
            values[rng.random(n) < 0.2] = np.round(values[:1])  # repeated and whole values
            records[axis] = values
        else:
            info = np.iinfo(kind)
            records[axis] = rng.integers(max(info.min, -int(extent)), min(info.max, int(extent)) + 1, n)
    records["intensity"] = rng.integers(0, 256, n)
    return records


@settings(max_examples=300, deadline=None)
@given(chunks(), st.sampled_from([0.3, 2.0, 7.5, 1e6]))
def test_grouping_equals_plain_python(records, s):
    sorted_records, groups = group_chunk(records, s, chunk=7)
    expected_bytes, expected = python_grouping(records, s)
    assert sorted_records.dtype == records.dtype
    assert sorted_records.tobytes() == expected_bytes
    assert groups.dtype == GROUP_DTYPE
    assert (groups["chunk"] == 7).all()
    got = [
        (i, j, start, count, low, high)
        for i, j, start, count, low, high in zip_equal(
            groups["i"].tolist(),
            groups["j"].tolist(),
            groups["start"].tolist(),
            groups["count"].tolist(),
            groups["min"].tolist(),
            groups["max"].tolist(),
        )
    ]
    assert got == expected


def test_cell_boundaries_and_negative_coordinates():
    records = np.zeros(6, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    records["x"] = [-2.0, -1e-7, 0.0, 1.9999999, 2.0, -2.0000002]
    records["y"] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    sorted_records, groups = group_chunk(records, 2.0)
    assert groups["i"].tolist() == [-2, -1, 0, 1]
    assert groups["count"].tolist() == [1, 2, 2, 1]
    assert sorted_records["x"].tolist() == [
        np.float32(-2.0000002),
        -2.0,
        np.float32(-1e-7),
        0.0,
        np.float32(1.9999999),
        2.0,
    ]


def test_empty_chunk():
    sorted_records, groups = group_chunk(np.zeros(0, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")]), 2.0)
    assert len(sorted_records) == 0 and len(groups) == 0


def test_coordinates_beyond_int64_tiles_are_refused():
    records = np.zeros(2, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    records["y"][1] = 1e300
    with pytest.raises(UserError, match=r"2\^62 tiles of 0\.5 m"):
        group_chunk(records, 0.5)
