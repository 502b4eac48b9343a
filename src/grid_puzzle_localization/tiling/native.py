"""The tiler's C++ library, ``libgrid_puzzle_localization_tiling.so`` (src/tiling_native/tile_grouping.cpp,
tile_writing.cpp and tile_index_json.cpp), loaded with ctypes from the library path that the package's
setup files set. Its loops run without the GIL, so threads and forked writers run them side by side."""

from __future__ import annotations

import ctypes
import functools

from grid_puzzle_localization.errors import UserError

LIBRARY = "libgrid_puzzle_localization_tiling.so"
_POINTER, _INT64 = ctypes.c_void_p, ctypes.c_int64
Xyz = _POINTER * 3  # addresses of x, y and z columns


class TileHeaderStruct(ctypes.Structure):
    """GpmTileHeader (tile_writing.hpp)."""

    _fields_ = [(name, ctypes.c_char_p) for name in ("before_width", "before_points", "after_points")]


class TileRowsStruct(ctypes.Structure):
    """GpmTileRows (tile_writing.hpp): addresses of int64 arrays and of the chunk address array."""

    _fields_ = [(name, _POINTER) for name in ("begin", "end", "chunk", "first", "last", "chunks")]


class TileColumnsStruct(ctypes.Structure):
    """GpmTileColumns (tile_index_json.hpp)."""

    _fields_ = [
        ("i", _POINTER),
        ("j", _POINTER),
        ("files", ctypes.c_char_p),
        ("points", _POINTER),
        ("bytes", _POINTER),
        ("lower", Xyz),
        ("upper", Xyz),
    ]


def c_strings(texts: list[str]) -> bytes:
    """The strings NUL-terminated, back to back: how the library takes a list of names."""
    return "".join(f"{text}\0" for text in texts).encode()


@functools.lru_cache(maxsize=None)
def library() -> ctypes.CDLL:
    """The library with its functions' signatures; UserError when it is not on the library path."""
    try:
        lib = ctypes.CDLL(LIBRARY)
    except OSError as err:
        raise UserError(
            f"cannot load {LIBRARY} ({err}); build the package (make build) and source its setup file"
            " (source build/setup.bash, or the install space's setup.bash)"
        ) from None
    lib.gpm_group_by_tile.restype = _INT64
    lib.gpm_group_by_tile.argtypes = [_POINTER, _INT64, _INT64, _POINTER, _POINTER, ctypes.c_double] + [_POINTER] * 3
    lib.gpm_write_tiles.restype = ctypes.c_int
    lib.gpm_write_tiles.argtypes = [
        ctypes.c_int,
        _INT64,
        ctypes.c_char_p,
        ctypes.c_char_p,
        _POINTER,
        ctypes.POINTER(TileHeaderStruct),
        ctypes.POINTER(TileRowsStruct),
        ctypes.POINTER(ctypes.c_char_p),
    ]
    lib.gpm_tiles_json.restype = _INT64
    lib.gpm_tiles_json.argtypes = [_INT64, ctypes.POINTER(TileColumnsStruct), ctypes.c_double, _INT64, _POINTER, _INT64]
    return lib
