"""Faults in the tile directory while the provider's TileStore runs (its prefetch thread included): a tile
deleted, truncated or made unreadable, and the whole directory removed and later restored. The store must
keep running: every bad tile is reported once naming the file, every other tile in the window is loaded
with exactly the points of its file, and tiles are served again once the directory is back."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np
import pytest
from fault_report import record
from fixtures.synthetic_tiles import write_tiles

from grid_puzzle_localization.pcd import read_pcd
from grid_puzzle_localization.pcd.reader import xyz_records
from grid_puzzle_localization.provider.tile_store import TileStore
from grid_puzzle_localization.provider.window import compute_window
from grid_puzzle_localization.tiles.directory import open_tile_directory

S = 2.0
CORRIDOR = [(i, j) for i in range(40) for j in range(-2, 3)]  # driven along +x


def make_unreadable(path):
    """chmod 000; root reads such a file anyway, so as root the tile becomes a directory (EISDIR)."""
    if os.geteuid() == 0:
        path.unlink()
        path.mkdir()
    else:
        path.chmod(0)


FAULTS = {
    "tile deleted": (10, lambda p: p.unlink()),
    "tile truncated": (14, lambda p: os.truncate(p, p.stat().st_size // 2)),
    "tile unreadable": (18, make_unreadable),
}


@pytest.fixture
def corridor(tmp_path):
    directory = tmp_path / "tiles"
    write_tiles(directory, CORRIDOR, S, count=20, seed=5)
    truth = {
        key: xyz_records(read_pcd(directory / f"{(key[0] + 0.5) * S}_{(key[1] + 0.5) * S}.pcd").points)
        for key in CORRIDOR
    }
    return directory, truth


def window_at(i: int):
    return compute_window((i + 0.5) * S, 0.5 * S, 0.0, S, 2, 3)


def test_tile_faults_while_the_store_runs(corridor, tmp_path):
    directory, truth = corridor
    tiles = open_tile_directory(directory, S)
    store = TileStore(tiles, prefetch=True)
    moved = tmp_path / "moved_away"
    reported: dict[str, str] = {}
    bad: set[tuple[int, int]] = set()
    fault_at: dict[str, float] = {}
    try:
        for i in range(36):
            window = window_at(i)
            if i == 4:  # the store is running; the faulty tiles lie well ahead of the window and prefetch
                assert store.wait_prefetch_idle(10)
                for name, (column, fault) in FAULTS.items():
                    fault(tiles.tile_path((column, 0)))
                    bad.add((column, 0))
                    fault_at[name] = time.monotonic()
            if i == 22:
                assert store.wait_prefetch_idle(10)
                shutil.move(directory, moved)
                fault_at["tile directory removed"] = time.monotonic()
            if i == 26:
                shutil.move(moved, directory)
                restored = time.monotonic()
            delta = store.update(window, [window_at(i + 1)])
            for path, reason in delta.newly_corrupt:
                assert str(path) in reason
                assert str(path) not in reported, "reported twice"
                reported[str(path)] = reason
                key = (round(float(path.name.split("_")[0]) / S - 0.5), round(float(path.stem.split("_")[1]) / S - 0.5))
                if 22 <= i < 26:
                    bad.add(key)
                else:
                    assert key in bad, f"{path} reported but not faulted: {reason}"
            if i == 26:
                assert delta.added, "no tile loaded after the directory came back"
                record(
                    "tile directory removed, then restored",
                    "entering tiles reported, loaded tiles kept",
                    round(time.monotonic() - restored, 3),
                    data_lost=f"{len(bad) - len(FAULTS)} tiles tried while it was gone stay marked bad",
                )
            # The loaded set: every tile of the window except the bad ones, each with its file's points.
            loaded = dict(store.loaded())
            wanted = {tuple(k) for k in tiles.existing_in(window).tolist()}
            assert set(loaded) == wanted - bad
            for key, points in loaded.items():
                assert np.array_equal(points, truth[key]), key
            assert store._thread.is_alive()
        for name, (column, _) in FAULTS.items():
            path = str(tiles.tile_path((column, 0)))
            assert path in reported, f"{name}: {path} never reported"
            record(name, f"reported once: {reported[path]}", None)
    finally:
        store.close()
