"""The tile directory's key store (sorted 64-bit codes, no numpy) against a brute-force selection: window
queries, bounds, reading from the index and from file names agree, and indices beyond the code's range are
refused with a message naming the index."""

from __future__ import annotations

import json
import random

import pytest
from fixtures.synthetic_tiles import write_tiles

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.window import compute_window
from grid_puzzle_localization.tiles.directory import decode_key, encode_key, open_tile_directory
from grid_puzzle_localization.tiling.index import FORMAT, INDEX_FILE, VERSION

S = 2.0
# Around the origin, so rows and columns of both signs (the code's order must follow (i, j) across zero).
KEYS = sorted({(random.Random(k).randint(-9, 9), random.Random(k + 1000).randint(-7, 7)) for k in range(150)})


@pytest.fixture(scope="module")
def tile_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("directory") / "tiles"
    write_tiles(d, KEYS, S, 2, seed=3)
    return d


def test_codes_sort_as_their_keys_and_decode_back():
    keys = [(i, j) for i in (-(2**31), -5, -1, 0, 1, 7, 2**31 - 1) for j in (-(2**31), -3, -1, 0, 2, 2**31 - 1)]
    codes = [encode_key(i, j) for i, j in keys]
    assert [decode_key(c) for c in codes] == keys
    assert sorted(codes) == codes == [encode_key(i, j) for i, j in sorted(keys)]
    for bad in ((2**31, 0), (0, -(2**31) - 1)):
        with pytest.raises(ValueError, match="beyond"):
            encode_key(*bad)


def test_window_queries_match_a_brute_force_selection(tile_dir):
    directory = open_tile_directory(tile_dir, S)
    assert len(directory) == len(KEYS) and directory.source == "scan"
    i, j = zip(*KEYS)
    assert directory.bounds == (min(i), max(i), min(j), max(j))
    rng = random.Random(0)
    for _ in range(200):
        window = compute_window(rng.uniform(-25, 25), rng.uniform(-20, 20), rng.uniform(-4, 4), S, rng.randint(0, 4), 2)
        expected = [(a, b) for a, b in KEYS if window.i_min <= a <= window.i_max and window.j_min <= b <= window.j_max]
        assert directory.existing_in(window) == expected
    assert directory.codes_in_box(-(10**12), 10**12, -(10**12), 10**12) == list(directory.codes)


def test_the_index_and_the_file_names_give_the_same_directory(tile_dir, tmp_path):
    by_names = open_tile_directory(tile_dir, S)
    index = {"format": FORMAT, "version": VERSION, "grid_size": S, "tiles": [{"key": list(k)} for k in KEYS]}
    copy = tmp_path / "indexed"
    copy.mkdir()
    (copy / INDEX_FILE).write_text(json.dumps(index))
    by_index = open_tile_directory(copy)
    assert by_index.source == "index" and list(by_index.codes) == list(by_names.codes)


def test_an_index_key_beyond_the_code_range_is_refused_naming_the_file(tmp_path):
    index = {"format": FORMAT, "version": VERSION, "grid_size": S, "tiles": [{"key": [2**31, 0]}]}
    (tmp_path / INDEX_FILE).write_text(json.dumps(index))
    with pytest.raises(UserError, match=rf"{INDEX_FILE}.*beyond"):
        open_tile_directory(tmp_path)
