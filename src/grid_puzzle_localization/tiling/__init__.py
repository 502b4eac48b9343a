"""Grid puzzle map tiling: cut a global map into tiles (``tile_map``), read the tile index
(``load_tile_index``; schema in the index module) and verify conservation (``verify_tiles``).

The names below are imported from their submodule on first use (PEP 562), so a process that only
reads the index (the tile provider) does not load the tiler and its progress bar."""

import importlib

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


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
