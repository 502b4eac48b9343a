"""atheris target: the tile index readers (the streaming key scan of tiles.directory, the full
tiling.index.load_tile_index, and open_tile_directory) on arbitrary index.json contents."""

from __future__ import annotations

import atheris
from harness import rejects_cleanly, run, scratch_dir

with atheris.instrument_imports(include=["grid_puzzle_localization"]):
    from grid_puzzle_localization.tiles.directory import open_tile_directory, read_index_keys
    from grid_puzzle_localization.tiling.index import INDEX_FILE, load_tile_index

DIRECTORY = scratch_dir()
PATH = DIRECTORY / INDEX_FILE


def read_all() -> None:
    read_index_keys(PATH, chunk_bytes=64)  # small chunks: matches across chunk boundaries
    tiles = open_tile_directory(DIRECTORY)
    assert len(tiles) > 0
    index = load_tile_index(DIRECTORY)
    for entry in index.tiles:
        index.path(entry)


def test_one_input(data: bytes) -> None:
    PATH.write_bytes(data)
    rejects_cleanly(read_all, DIRECTORY)


if __name__ == "__main__":
    run(test_one_input)
