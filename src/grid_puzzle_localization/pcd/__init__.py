"""PCD v0.7 input and output with numpy: ascii, binary and binary_compressed (LZF), any fields.

Points are numpy structured arrays whose field names and dtypes are those of the file. Errors are
``grid_puzzle_localization.errors.PcdError`` naming the file and the problem.
"""

from grid_puzzle_localization.pcd.header import ENCODINGS, PcdHeader, read_pcd_header
from grid_puzzle_localization.pcd.merge import merge_pcds
from grid_puzzle_localization.pcd.reader import PcdChunks, PcdCloud, iter_pcd_chunks, read_pcd, xyz_array
from grid_puzzle_localization.pcd.writer import PcdStreamWriter, write_pcd

__all__ = [
    "ENCODINGS",
    "PcdChunks",
    "PcdCloud",
    "PcdHeader",
    "PcdStreamWriter",
    "iter_pcd_chunks",
    "merge_pcds",
    "read_pcd",
    "read_pcd_header",
    "write_pcd",
    "xyz_array",
]
