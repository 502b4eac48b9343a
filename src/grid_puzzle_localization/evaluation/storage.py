"""Storage figures: the global map's bytes, and the tiles' bytes and file count with PCD header and
file-system block overhead shown separately (from the tiler's own verification report); the same for
keyframe-stitched block maps and fixed-size overlapping submaps (block directories). Each entry has
the overlap factor (stored points / map points) and the mean bytes per file."""

from __future__ import annotations

import os
from pathlib import Path

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
        "overlap_factor": 1.0,
        "mean_bytes_per_file": float(st.st_size),
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
        "overlap_factor": r.points_tiles / r.points_in if r.points_in else float("nan"),
        "mean_bytes_per_file": r.bytes_tiles_total / r.tiles if r.tiles else float("nan"),
        "problems": list(r.problems),
    }


def block_dir_storage(directory: str | os.PathLike) -> dict:
    """A block directory (`gpm blocks` or `gpm submaps`): its PCD files, and stored points over the
    points of the map they represent (the index's ``map_points``)."""
    from grid_puzzle_localization.blocks.store import read_block_index

    index = read_block_index(directory)
    files = [Path(directory) / b.file for b in index.blocks]
    stats = [f.stat() for f in files]
    total = sum(st.st_size for st in stats)
    header = sum(read_pcd_header(f).header_bytes for f in files)
    stored = sum(b.points for b in index.blocks)
    return {
        "files": len(files),
        "bytes": total,
        "header_bytes": header,
        "data_bytes": total - header,
        "disk_bytes": sum(st.st_blocks * 512 for st in stats),
        "points_map": index.map_points,
        "points_stored": stored,
        "overlap_factor": stored / index.map_points if index.map_points else float("nan"),
        "mean_bytes_per_file": total / len(files) if files else float("nan"),
    }


def storage_figures(
    global_map: str | os.PathLike,
    tile_dir: str | os.PathLike | None,
    block_dir: str | os.PathLike | None = None,
    submap_dir: str | os.PathLike | None = None,
) -> dict:
    """What summary.json holds under ``storage``."""
    figures: dict = {"global_map": map_storage(global_map)}
    if tile_dir is not None:
        figures["tiles"] = tiles_storage(tile_dir, global_map)
    if block_dir is not None:
        figures["block_maps"] = block_dir_storage(block_dir)
    if submap_dir is not None:
        figures["fixed_submaps"] = block_dir_storage(submap_dir)
    return figures
