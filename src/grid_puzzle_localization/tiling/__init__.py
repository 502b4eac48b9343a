"""Grid puzzle map tiling: cut a global map into tiles (``tile_map``), read the tile index
(``load_tile_index``; schema in the index module) and verify conservation (``verify_tiles``)."""

from grid_puzzle_localization.tiling.index import (
    AUTOWARE_METADATA_FILE,
    INDEX_FILE,
    TileEntry,
    TileIndex,
    load_tile_index,
)
from grid_puzzle_localization.tiling.tiler import TileConfig, TileResult, tile_map
from grid_puzzle_localization.tiling.verify import VerifyReport, verify_tiles

__all__ = [
    "AUTOWARE_METADATA_FILE",
    "INDEX_FILE",
    "TileConfig",
    "TileEntry",
    "TileIndex",
    "TileResult",
    "VerifyReport",
    "load_tile_index",
    "tile_map",
    "verify_tiles",
]
