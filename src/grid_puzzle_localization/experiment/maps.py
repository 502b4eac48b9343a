"""Map preparation for the experiment: the grid puzzle tiles of the global map, cut once with the
tiler and reused while their index matches the map and the grid size."""

from __future__ import annotations

import os
from pathlib import Path

from grid_puzzle_localization.errors import UserError


def ensure_tiles(global_map: str | os.PathLike, tile_dir: str | os.PathLike, grid_size_m: float) -> Path:
    """``tile_dir`` holding the tiles of ``global_map`` with side ``grid_size_m``; cuts them when the
    directory has no tile index, reuses them when the index has this grid size and is newer than the
    map, and refuses a directory tiled otherwise."""
    from grid_puzzle_localization.tiling.index import load_tile_index
    from grid_puzzle_localization.tiling.tiler import TileConfig, tile_map

    tile_dir = Path(tile_dir)
    if tile_dir.is_dir() and any(tile_dir.iterdir()):
        index = load_tile_index(tile_dir)
        if index.grid_size != grid_size_m:
            raise UserError(
                f"{tile_dir} holds tiles of {index.grid_size} m, not {grid_size_m} m: remove it or pass --tiles"
            )
        newest_tile = max(p.stat().st_mtime for p in tile_dir.iterdir())
        if newest_tile < Path(global_map).stat().st_mtime:
            raise UserError(f"{tile_dir} is older than {global_map}: remove it so the tiles are cut again")
        return tile_dir
    tile_dir.parent.mkdir(parents=True, exist_ok=True)
    print(f"gpm experiment: cutting {global_map} into {grid_size_m} m tiles in {tile_dir}")
    tile_map([global_map], tile_dir, TileConfig(grid_size=grid_size_m, progress=False, force=True))
    return tile_dir
