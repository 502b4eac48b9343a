"""PCD v0.7 input and output with numpy: ascii, binary and binary_compressed (LZF), any fields.

Points are numpy structured arrays whose field names and dtypes are those of the file. Errors are
``grid_puzzle_localization.errors.PcdError`` naming the file and the problem.

The names below are imported from their submodule on first use (lazy_exports), so a process that
only reads (the tile provider) does not load the writer, the merger and what they import.
"""

from grid_puzzle_localization.util.lazy_exports import lazy_exports

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
    "xyz_records": "reader",
    "PcdStreamWriter": "writer",
    "write_pcd": "writer",
}
__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
