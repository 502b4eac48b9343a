"""Grouping a chunk of points by tile: a stable sort by tile (i, j) = (floor(x / s), floor(y / s)),
computed in float64 (as grid.tile_index), and one row per tile with its point range and bounds.

The sort runs in the package's C++ library (native.py: src/tiling_native/tile_grouping.cpp, without the GIL,
so that chunks are grouped on several threads at once): one counting sort over the
chunk's tiles does what took a dozen numpy passes and their temporaries, three times as fast.

Stability matters: points keep their input order inside a tile, so the output is deterministic and
a tile read back equals the input points of that cell, in order.
"""

from __future__ import annotations

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiling import native

# One row per (tile, chunk): where the tile's points sit in the sorted chunk, how many there are,
# and their x, y, z bounds [m]. The layout of GpmTileGroup in tile_grouping.hpp.
GROUP_DTYPE = np.dtype(
    [
        ("i", "<i8"),
        ("j", "<i8"),
        ("chunk", "<i8"),
        ("start", "<i8"),
        ("count", "<i8"),
        ("min", "<f8", (3,)),
        ("max", "<f8", (3,)),
    ]
)
# GpmFieldType in tile_grouping.hpp
_FIELD_TYPES = {"f4": 0, "f8": 1, "i1": 2, "i2": 3, "i4": 4, "i8": 5, "u1": 6, "u2": 7, "u4": 8, "u8": 9}


def group_chunk(records: np.ndarray, s: float, chunk: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Sorts ``records`` by tile of side ``s`` [m]; returns the sorted records and one GROUP_DTYPE row
    per tile present (rows in (i, j) order, ``chunk`` copied into each row). x, y and z must be finite."""
    records = np.ascontiguousarray(records)
    n = len(records)
    xyz = [records.dtype.fields[name] for name in ("x", "y", "z")]
    offsets = np.array([offset for _, offset in xyz], dtype=np.int64)
    types = np.array([_FIELD_TYPES[dtype.str[1:]] for dtype, _ in xyz], dtype=np.int32)
    sorted_records = np.empty_like(records)
    rows = np.empty(n, dtype=GROUP_DTYPE)  # room for a tile per point; only the rows written are touched
    scratch = np.empty(2 * n, dtype=np.int64)
    tiles = native.library().gpm_group_by_tile(
        records.ctypes.data,
        n,
        records.dtype.itemsize,
        offsets.ctypes.data,
        types.ctypes.data,
        s,
        sorted_records.ctypes.data,
        rows.ctypes.data,
        scratch.ctypes.data,
    )
    if tiles < 0:
        raise UserError(
            f"a point lies more than 2^62 tiles of {s:g} m from the origin; check the map's coordinates and --grid-size"
        )
    groups = rows[:tiles].copy()
    groups["chunk"] = chunk
    return sorted_records, groups


def merge_stats(rows: np.ndarray) -> np.ndarray:
    """Collapses rows of the same tile into one (counts summed, bounds widened), sorted by (i, j);
    ``chunk`` and ``start`` of the result are meaningless."""
    if len(rows) == 0:
        return rows
    rows = rows[np.lexsort((rows["j"], rows["i"]))]
    starts = _run_starts(rows["i"], rows["j"])
    out = rows[starts].copy()
    out["count"] = np.add.reduceat(rows["count"], starts)
    out["min"] = np.minimum.reduceat(rows["min"], starts, axis=0)
    out["max"] = np.maximum.reduceat(rows["max"], starts, axis=0)
    return out


def tile_spans(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For rows sorted by tile: index of each tile's first row and one past its last."""
    starts = _run_starts(rows["i"], rows["j"])
    return starts, np.append(starts[1:], len(rows))[: len(starts)]


def key_positions(sorted_i: np.ndarray, sorted_j: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Position of each key (i, j) among the distinct keys (sorted_i, sorted_j), sorted by (i, j);
    every key must be present. Each coordinate is replaced by its rank among the distinct values, so
    the pair fits one int64 that sorts like (i, j) whatever the coordinates' range."""
    ui, uj = np.unique(sorted_i), np.unique(sorted_j)

    def dense(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.searchsorted(ui, a) * len(uj) + np.searchsorted(uj, b)

    return np.searchsorted(dense(sorted_i, sorted_j), dense(i, j))


def _run_starts(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Indices where a run of equal (i, j) begins (arrays sorted by (i, j))."""
    change = np.ones(len(i), dtype=bool)
    change[1:] = (i[1:] != i[:-1]) | (j[1:] != j[:-1])
    return np.flatnonzero(change)
