"""Map preparation for the experiment: the grid puzzle tiles of the global map, cut once with the
tiler and reused while their index matches the map and the grid size, or a map store serving them."""

from __future__ import annotations

import math
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


def check_store_tiles(url: str, grid_size_m: float) -> str:
    """``url``, a map store (docs/map_store.md) whose index lists tiles of side ``grid_size_m``; UserError naming
    the URL when it cannot be reached (with nothing of it in the cache) or is tiled otherwise. The runs' localizer
    and provider fetch the tiles themselves."""
    from grid_puzzle_localization.tiles.map_store import MapStore

    store = MapStore(url)
    try:
        if not math.isclose(store.grid_size, grid_size_m, rel_tol=1e-9):
            raise UserError(f"{url} serves tiles of {store.grid_size:g} m, not {grid_size_m:g} m: pass --grid-size")
    finally:
        store.close()
    return url


EMPTY_MAP_POINT = (1.0e5, 1.0e5, 0.0)  # [m] the empty map's one point, far from any route


def write_empty_map(directory: str | os.PathLike, grid_size_m: float) -> tuple[Path, Path]:
    """An empty map in ``directory`` for the runs that measure each process's floor: a PCD whose one point
    lies far from any route (a tile directory must list a tile), and its tiles. Returns (PCD path, tile
    directory)."""
    import numpy as np

    from grid_puzzle_localization.pcd.writer import write_pcd
    from grid_puzzle_localization.tiling.tiler import TileConfig, tile_map

    directory = Path(directory)
    pcd, tiles = directory / "empty.pcd", directory / f"tiles_s{grid_size_m:g}"
    write_pcd(pcd, np.array([EMPTY_MAP_POINT], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
    tile_map([pcd], tiles, TileConfig(grid_size=grid_size_m, progress=False, force=True))
    return pcd, tiles


SUBMAP_OVERLAP = 0.5  # overlap ratio of the fixed-size submaps in the storage comparison (grid puzzle paper, Fig. 1)


def _fresh(directory: Path, inputs: list[Path], params: dict) -> bool:
    """True when ``directory`` holds a block index built with ``params`` after every input changed."""
    from grid_puzzle_localization.blocks.store import INDEX_FILE, read_block_index

    if not (directory / INDEX_FILE).is_file():
        return False
    index = read_block_index(directory)
    newer = (directory / INDEX_FILE).stat().st_mtime >= max(p.stat().st_mtime for p in inputs)
    return newer and all(index.params.get(k) == v for k, v in params.items())


def ensure_blocks(global_map: Path, ground_truth: Path, block_dir: Path, block_size_m: float) -> Path:
    """Keyframe-stitched blocks (Algorithm 1) of pseudo-scans cut from ``global_map`` along the ground
    truth, so block_map mode localizes against the same prior map as the other modes: blocks hold the
    map's own points (no voxel filter). Reused while their index matches."""
    from grid_puzzle_localization.blocks.builder import BlockConfig, build_blocks
    from grid_puzzle_localization.blocks.map_scans import DEFAULT_SCAN_RADIUS, MapSubsets, map_scans
    from grid_puzzle_localization.blocks.poses import read_tum
    from grid_puzzle_localization.blocks.store import write_block_dir
    from grid_puzzle_localization.pcd import read_pcd, xyz_array

    config = BlockConfig(block_size=block_size_m, voxel=0.0).checked()
    params = {
        "block_size": config.block_size,
        "keyframe_spacing": config.keyframe_spacing,
        "voxel": config.voxel,
        "scan_radius": DEFAULT_SCAN_RADIUS,
        "map": str(global_map),
        "trajectory": str(ground_truth),
    }
    if _fresh(block_dir, [global_map, ground_truth], params):
        return block_dir
    print(
        f"gpm experiment: stitching {block_size_m:g} m block maps of {global_map} along {ground_truth} in {block_dir}"
    )
    points = xyz_array(read_pcd(global_map).points)
    scans = map_scans(points, read_tum(ground_truth), DEFAULT_SCAN_RADIUS)
    builder = build_blocks(scans, config, sets=MapSubsets(points, config.voxel))
    extras = ((b.points, b.centroid, {"keyframes": b.keyframes}) for b in builder.blocks)
    write_block_dir(block_dir, extras, "keyframe_blocks", params, builder.map_points(), force=True)
    return block_dir


def ensure_submaps(global_map: Path, submap_dir: Path, side_m: float) -> Path:
    """Fixed-size overlapping submaps (side ``side_m``, overlap SUBMAP_OVERLAP) of ``global_map``, for
    the storage comparison. Reused while their index matches."""
    from grid_puzzle_localization.blocks.fixed_cut import SubmapConfig
    from grid_puzzle_localization.commands.submaps import write_submaps
    from grid_puzzle_localization.pcd import read_pcd, xyz_array

    config = SubmapConfig(side_m, SUBMAP_OVERLAP).checked()
    params = {"side": config.side, "overlap": config.overlap, "map": str(global_map)}
    if _fresh(submap_dir, [global_map], params):
        return submap_dir
    write_submaps(xyz_array(read_pcd(global_map).points), config, submap_dir, global_map, force=True)
    return submap_dir
