"""TileReferences: the window's tiles by name against a brute-force selection, the prefetch list, and a tile
directory rewritten or removed under a running provider."""

from __future__ import annotations

import random
import shutil
from types import SimpleNamespace

import pytest
from fixtures.synthetic_tiles import write_tiles

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.tile_references import PREFETCH_MAX_TILES, TileReferences, index_revision
from grid_puzzle_localization.provider.window import PoseSample, WindowConfig, WindowTracker
from grid_puzzle_localization.tiles.directory import decode_key, open_tile_directory

S = 2.0
# A 30 x 20 map with holes (tiles that do not exist must never be named).
KEYS = [(i, j) for i in range(30) for j in range(20) if (i * 7 + j * 3) % 11 != 0]


@pytest.fixture
def tile_dir(tmp_path):
    write_tiles(tmp_path / "tiles", KEYS, S, 4, seed=1)
    return tmp_path / "tiles"


def brute_force(window) -> set[tuple[int, int]]:
    return {(i, j) for i, j in KEYS if window.i_min <= i <= window.i_max and window.j_min <= j <= window.j_max}


def test_deltas_follow_a_drive_and_prefetch_names_only_tiles_ahead_outside_the_window(tile_dir):
    refs = TileReferences(open_tile_directory(tile_dir, S))
    tracker = WindowTracker(WindowConfig(n=3, k=2), S)
    mirror: set[tuple[int, int]] = set()
    prefetched_then_entered = 0
    last_prefetch: set[tuple[int, int]] = set()
    for step in range(60):
        window = tracker.update(PoseSample(3.0 + step * 0.9, 15.0 + step * 0.2, float(step)))
        if window is None:
            continue
        delta = refs.update(window, tracker.predicted_windows())
        assert not set(delta.added) & mirror
        assert set(delta.removed) <= mirror
        mirror = (mirror - set(delta.removed)) | set(delta.added)
        assert mirror == brute_force(window) == set(refs.loaded())
        assert set(delta.prefetch) <= set(KEYS) and not set(delta.prefetch) & mirror
        assert len(delta.prefetch) == len(set(delta.prefetch))
        prefetched_then_entered += len(set(delta.added) & last_prefetch)
        last_prefetch = set(delta.prefetch)
    assert prefetched_then_entered > 20  # the heading-aware guess is right most of the time
    assert refs.paths() == [refs.directory.tile_path(k) for k in sorted(mirror)]


def test_a_rewritten_directory_is_reopened_and_its_whole_window_listed_again(tile_dir):
    refs = TileReferences(open_tile_directory(tile_dir, S))
    window = WindowTracker(WindowConfig(n=2, k=0), S).update(PoseSample(10.0, 10.0, 0.0))
    first = refs.update(window)
    assert refs.refresh() is False
    before = refs.revision
    write_tiles(tile_dir, [(100, 100)], S, 4, seed=2)  # a new tile file: the directory changes
    assert index_revision(tile_dir) != before
    assert refs.refresh() is True
    assert (100, 100) in {decode_key(c) for c in refs.directory.codes}
    again = refs.update(window)
    assert sorted(again.added) == sorted(first.added) and again.removed == []


def test_a_directory_that_disappears_is_a_user_error_naming_it(tile_dir):
    refs = TileReferences(open_tile_directory(tile_dir, S))
    shutil.rmtree(tile_dir)
    with pytest.raises(UserError, match=str(tile_dir)):
        refs.refresh()


def test_deltas_and_prefetch_equal_a_brute_force_listing_for_jumps_growth_and_overlaps(tile_dir):
    """Windows that jump, grow, shrink and overlap in every way: the delta is the difference of the two windows'
    tile sets and the prefetch list the ahead windows' tiles outside the window, in the order of the windows,
    each once, all as a brute-force listing over the map's tiles gives them."""
    refs = TileReferences(open_tile_directory(tile_dir, S))
    rng = random.Random(3)
    held: set[tuple[int, int]] = set()
    for _ in range(300):
        window, *ahead = (random_window(rng) for _ in range(rng.randrange(1, 5)))
        delta = refs.update(window, ahead)
        wanted = brute_force(window)
        assert delta.added == sorted(wanted - held)
        assert delta.removed == sorted(held - wanted)
        held = wanted
        expected: list[tuple[int, int]] = []
        for w in ahead:
            expected += [key for key in sorted(brute_force(w) - wanted) if key not in expected]
        assert delta.prefetch == expected[:PREFETCH_MAX_TILES]


class BoxWindow(SimpleNamespace):
    @property
    def bounds(self) -> tuple[int, int, int, int]:
        return self.i_min, self.i_max, self.j_min, self.j_max


def random_window(rng: random.Random) -> BoxWindow:
    """A box of up to 12 x 12 tiles anywhere on the 30 x 20 map or across its edges."""
    i0, j0 = rng.randrange(-5, 32), rng.randrange(-5, 22)
    return BoxWindow(i_min=i0, i_max=i0 + rng.randrange(0, 12), j_min=j0, j_max=j0 + rng.randrange(0, 12))
