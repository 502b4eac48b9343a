"""Concatenating PCD files with the same fields into one binary PCD, streamed."""

from __future__ import annotations

import os
from collections.abc import Sequence

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.header import read_pcd_header
from grid_puzzle_localization.pcd.reader import iter_pcd_chunks
from grid_puzzle_localization.pcd.writer import PcdStreamWriter


def merge_pcds(inputs: Sequence[str | os.PathLike], output: str | os.PathLike) -> int:
    """Writes the finite points of all ``inputs`` (in order) to ``output``; returns the point count."""
    if not inputs:
        raise PcdError(f"{output}: nothing to merge (no input files)")
    dtype = read_pcd_header(inputs[0]).dtype
    with PcdStreamWriter(output, dtype) as writer:
        for path in inputs:
            chunks = iter_pcd_chunks(path)
            if chunks.header.dtype != dtype:
                raise PcdError(f"{path}: fields differ from {inputs[0]}; only clouds with the same fields merge")
            for chunk in chunks:
                writer.append(chunk)
    return writer.points
