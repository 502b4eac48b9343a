"""Grid puzzle map tiling: cut a global map into tiles (``tile_map``), read the tile index
(``load_tile_index``; schema in the index module) and verify conservation (``verify_tiles``).

The names below are imported from their submodule on first use (lazy_exports), so a process that
only reads the index (the tile provider) does not load the tiler and its progress bar."""

from grid_puzzle_localization.util.lazy_exports import lazy_exports

_EXPORTS = {
    "AUTOWARE_METADATA_FILE": "index",
    "INDEX_FILE": "index",
    "TileEntry": "index",
    "TileIndex": "index",
    "load_tile_index": "index",
    "TileConfig": "tiler",
    "TileResult": "tiler",
    "tile_map": "tiler",
    "VerifyReport": "verify",
    "verify_tiles": "verify",
}
__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
