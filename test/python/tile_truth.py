"""Brute-force truth for tile selections: list the directory and read the tile centres off the names."""

import math
import os


def brute_force_window_files(directory, bounds, s):
    """(i, j) of the tile files in ``directory`` whose index lies in ``bounds`` = (i_min, i_max, j_min, j_max)."""
    i_min, i_max, j_min, j_max = bounds
    out = set()
    for name in os.listdir(directory):
        stem, ext = os.path.splitext(name)
        parts = stem.split("_")
        if ext != ".pcd" or len(parts) != 2:
            continue
        try:
            cx, cy = float(parts[0]), float(parts[1])
        except ValueError:
            continue
        i, j = math.floor(cx / s), math.floor(cy / s)
        if (i + 0.5) * s != cx or (j + 0.5) * s != cy:
            continue
        if i_min <= i <= i_max and j_min <= j <= j_max:
            out.add((i, j))
    return out
