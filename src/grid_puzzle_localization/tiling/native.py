"""The tiler's C++ library, ``libgrid_puzzle_localization_tiling.so`` (src/tiling_native/tile_grouping.cpp
and tile_writing.cpp), loaded with ctypes from the library path that the package's
setup files set. Its loops run without the GIL, so threads and forked writers run them side by side."""

from __future__ import annotations

import ctypes
import functools

from grid_puzzle_localization.errors import UserError

LIBRARY = "libgrid_puzzle_localization_tiling.so"
_POINTER, _INT64 = ctypes.c_void_p, ctypes.c_int64


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
    # dir_fd, tiles, names, spills, counts, the three header texts, the six row arrays, failed_path
    lib.gpm_write_tiles.argtypes = [ctypes.c_int, _INT64, ctypes.c_char_p, ctypes.c_char_p, _POINTER]
    lib.gpm_write_tiles.argtypes += [ctypes.c_char_p] * 3 + [_POINTER] * 6 + [ctypes.POINTER(ctypes.c_char_p)]
    return lib
