"""PCD v0.7 input and output with numpy: ascii, binary and binary_compressed (LZF), any fields.

Points are numpy structured arrays whose field names and dtypes are those of the file. Errors are
``grid_puzzle_localization.errors.PcdError`` naming the file and the problem.

The names below are imported from their submodule on first use (PEP 562), so a process that only
reads (the tile provider) does not load the writer, the merger and what they import.
"""

import importlib

_EXPORTS = {
    "ENCODINGS": "header",
    "PcdHeader": "header",
    "read_pcd_header": "header",
    "merge_pcds": "merge",
    "PcdChunks": "reader",
    "PcdCloud": "reader",
    "iter_pcd_chunks": "reader",
    "read_pcd": "reader",
    "xyz_array": "reader",
    "PcdStreamWriter": "writer",
    "write_pcd": "writer",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
