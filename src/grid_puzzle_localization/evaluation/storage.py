"""Storage figures: the global map's bytes, and the tiles' bytes and file count with PCD header and
file-system block overhead shown separately (from the tiler's own verification report)."""

from __future__ import annotations

import os
from pathlib import Path

from grid_puzzle_localization.blocks.storage import storage_table
from grid_puzzle_localization.pcd.header import read_pcd_header


def map_storage(path: str | os.PathLike) -> dict[str, int]:
    """One map file: its size, header and data bytes, and the bytes allocated on disk."""
    st = Path(path).stat()
    header = read_pcd_header(path).header_bytes
    return {
        "files": 1,
        "bytes": st.st_size,
        "header_bytes": header,
        "data_bytes": st.st_size - header,
        "disk_bytes": st.st_blocks * 512,
    }


def tiles_storage(tile_dir: str | os.PathLike, global_map: str | os.PathLike) -> dict:
    """Tiles of ``global_map`` in ``tile_dir``, checked by the tiler's verification (point
    conservation). ``data_overhead_bytes`` is tile point data minus the map's finite point data:
    zero when no point is duplicated, the paper's "no extra storage"."""
    from grid_puzzle_localization.tiling.verify import verify_tiles

    r = verify_tiles(tile_dir, [global_map])
    return {
        "files": r.tiles,
        "bytes": r.bytes_tiles_total,
        "header_bytes": r.bytes_tiles_headers,
        "data_bytes": r.bytes_tiles_data,
        "disk_bytes": r.bytes_tiles_disk,
        "data_overhead_bytes": r.bytes_tiles_data - r.bytes_in_data,
        "points_map": r.points_in,
        "points_tiles": r.points_tiles,
        "problems": list(r.problems),
    }


def storage_figures(
    global_map: str | os.PathLike, tile_dir: str | os.PathLike | None, block_dir: str | os.PathLike | None = None
) -> dict:
    """What summary.json holds under ``storage``: the byte breakdown of the map and the tiles, and one
    row per representation (global map, tiles, block maps) with its overlap factor, from the block
    maps' storage table."""
    figures: dict = {"global_map": map_storage(global_map)}
    if tile_dir is not None:
        figures["tiles"] = tiles_storage(tile_dir, global_map)
    figures["representations"] = [row.as_dict() for row in storage_table(global_map, tile_dir, block_dir)]
    return figures
