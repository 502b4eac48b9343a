"""Grid puzzle tile geometry: which tile a point belongs to, the tile's centre, and its file name.

Tiles are squares of side ``s`` metres anchored at the map origin. Point ``(x, y)`` lies in tile
``(i, j) = (floor(x / s), floor(y / s))`` (computed in float64), whose centre is
``c = (i + 1/2) * s`` (the paper's Eq. 1 and 2). A tile file is named ``{cx}_{cy}.pcd``.

File-name number format: each centre is written in plain fixed-point decimal (no exponent), with at
least one and at most 17 fractional digits: the fewest digits whose value lies within ``s * 1e-9`` of
the exact centre. A leading ``-`` marks negative values; ``_`` separates x from y, so a name splits
unambiguously. Examples for ``s = 2``: ``1.0_-3.0``; for ``s = 0.5``: ``0.25_-0.75``; for ``s = 0.2``:
``0.3_0.1`` (not ``0.30000000000000004``). Parsing recovers the tile index exactly:
``i = floor(cx / s)`` is safe because the written centre is within ``s * 1e-9`` of the middle of the tile.
"""

from __future__ import annotations

import functools
import math
import re
from fractions import Fraction
from typing import TYPE_CHECKING

from grid_puzzle_localization.errors import UserError

if TYPE_CHECKING:
    import numpy as np

_NUMBER = r"-?\d+\.\d+"
_STEM = re.compile(rf"^({_NUMBER})_({_NUMBER})$")


def check_grid_size(s: float) -> float:
    """Returns ``s`` as a float, or raises UserError when it is not a finite positive length."""
    s = float(s)
    if not (math.isfinite(s) and s > 0.0):
        raise UserError(f"grid size must be a positive number of metres (got {s}); for example --grid-size 2")
    return s


def tile_index(coord: np.ndarray | float, s: float) -> np.ndarray | int:
    """Tile index floor(coord / s) along one axis, in float64 so large (UTM) coordinates stay exact. A
    number needs no numpy (the provider node runs without it)."""
    if isinstance(coord, (int, float)):
        return math.floor(float(coord) / s)
    import numpy as np

    idx = np.floor(np.asarray(coord, dtype=np.float64) / s).astype(np.int64)
    return idx if idx.ndim else int(idx)


def tile_center(i: int, s: float) -> float:
    """Centre coordinate of tile index ``i`` [m]: i * s + s / 2."""
    return (i + 0.5) * s


@functools.lru_cache(maxsize=1 << 16)  # a tiler names ~1e5 tiles sharing few distinct i, j
def format_center(i: int, s: float) -> str:
    """Decimal text of the centre of tile ``i`` (see module docstring for the format)."""
    exact = (Fraction(i) + Fraction(1, 2)) * Fraction(s)
    tolerance = Fraction(s) * Fraction(1, 10**9)
    for digits in range(1, 18):
        text = f"{float(exact):.{digits}f}"
        if abs(Fraction(text) - exact) <= tolerance:
            return text
    return f"{float(exact):.17f}"


def tile_stem(i: int, j: int, s: float) -> str:
    """File stem ``{cx}_{cy}`` of tile (i, j)."""
    return f"{format_center(i, s)}_{format_center(j, s)}"


def tile_filename(i: int, j: int, s: float) -> str:
    return tile_stem(i, j, s) + ".pcd"


def parse_tile_stem(stem: str, s: float) -> tuple[int, int]:
    """Tile index (i, j) of a file stem ``{cx}_{cy}``. Raises ValueError when the stem is not a tile
    name or its centre is not the middle of a tile of side ``s``."""
    m = _STEM.match(stem)
    if not m:
        raise ValueError(f"'{stem}' is not a tile name of the form <cx>_<cy> (e.g. 1.0_-3.0)")
    ij = tuple(math.floor(float(text) / s) for text in m.groups())
    if tile_stem(ij[0], ij[1], s) != stem:
        raise ValueError(f"'{stem}' is not the centre of a {s} m tile (expected {tile_stem(ij[0], ij[1], s)})")
    return ij  # type: ignore[return-value]
