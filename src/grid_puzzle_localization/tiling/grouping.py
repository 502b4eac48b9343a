"""Grouping a chunk of points by tile, vectorised: tile index per point (float64, grid.tile_index),
a stable sort by tile, and one row per tile with its point range and statistics.

Stability matters: points keep their input order inside a tile, so the output is deterministic and
a tile read back equals the input points of that cell, in order.
"""

from __future__ import annotations

import numpy as np

from grid_puzzle_localization.grid import tile_index

# One row per (tile, chunk): where the tile's points sit in the sorted chunk, how many there are,
# and their x, y, z bounds [m].
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
_DIGIT_BITS = 16


def stable_tile_order(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Permutation sorting points by (i, j), keeping input order among equal keys. An LSD radix sort
    over 16-bit digits of a dense key (numpy sorts uint16 with a counting sort), which beats a
    comparison sort several times on millions of points."""
    if len(i) == 0:
        return np.empty(0, dtype=np.int64)
    di = i - i.min()
    dj = j - j.min()
    span_j = int(dj.max()) + 1
    top = int(di.max()) * span_j + span_j - 1
    if top >= 1 << 62:  # astronomically sparse extent: fall back to a comparison sort
        return np.lexsort((j, i))
    dense = (di * span_j + dj).astype(np.uint64)
    order = None
    shift = 0
    while True:
        keys = dense if order is None else dense[order]
        digit = ((keys >> np.uint64(shift)) & np.uint64(0xFFFF)).astype(np.uint16)
        step = np.argsort(digit, kind="stable")
        order = step if order is None else order[step]
        shift += _DIGIT_BITS
        if top >> shift == 0:
            return order


def group_chunk(records: np.ndarray, s: float, chunk: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Sorts ``records`` by tile of side ``s`` [m]; returns the sorted records and one GROUP_DTYPE row
    per tile present (rows in (i, j) order, ``chunk`` copied into each row)."""
    i = tile_index(records["x"], s)
    j = tile_index(records["y"], s)
    order = stable_tile_order(i, j)
    records, i, j = take_records(records, order), i[order], j[order]
    n = len(records)
    if n == 0:
        return records, np.empty(0, dtype=GROUP_DTYPE)
    starts = _run_starts(i, j)
    groups = np.empty(len(starts), dtype=GROUP_DTYPE)
    groups["i"] = i[starts]
    groups["j"] = j[starts]
    groups["chunk"] = chunk
    groups["start"] = starts
    groups["count"] = np.diff(np.append(starts, n))
    for axis, name in enumerate(("x", "y", "z")):
        values = records[name]
        groups["min"][:, axis] = np.minimum.reduceat(values, starts)
        groups["max"][:, axis] = np.maximum.reduceat(values, starts)
    return records, groups


def take_records(records: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``records[order]`` for a structured array, through a byte-row view: numpy's fancy indexing of
    structured records is about 20x slower than taking rows of bytes."""
    raw = np.ascontiguousarray(records).view(np.uint8).reshape(len(records), records.dtype.itemsize)
    return np.take(raw, order, axis=0).reshape(-1).view(records.dtype)


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
