"""The tiles of the window by reference: which tile files enter and leave the window, and which are
likely to enter next, without reading a single point (the localizer reads the files itself).

``TileReferences.update(window, ahead)`` returns the keys that entered and left since the last update
and the prefetch list (tiles of the ``ahead`` windows, most likely first, that are not in the window).
``refresh()`` notices a tile directory rewritten under the running node (a new index revision) and
reopens it; the caller then sends the whole window again as a reset. A map given by URL (a map store,
tiles/map_store.py) is listed by the index the store holds, and its revision is the store's: the caller
polls the store, and refresh() takes up the revision that poll brought. Not thread-safe (the provider
serialises its updates).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Tuple

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.window import Window
from grid_puzzle_localization.tiles.directory import Key, TileDirectory, decode_key, open_tile_directory
from grid_puzzle_localization.tiling.index import INDEX_FILE

if TYPE_CHECKING:
    from grid_puzzle_localization.tiles.map_store import MapStore

PREFETCH_MAX_TILES = 256  # bound of one prefetch list: the localizer's byte budget bounds what it reads


def index_revision(path: Path) -> str:
    """Identity of a tile directory's contents: of its index file when there is one (the tiler replaces
    it by rename, so a rewrite changes inode, time or size), else of the directory itself (adding or
    removing a tile file changes its modification time)."""
    index = path / INDEX_FILE
    try:
        st = os.stat(index)
        return f"index:{st.st_ino}:{st.st_mtime_ns}:{st.st_size}"
    except FileNotFoundError:
        st = os.stat(path)
        return f"scan:{st.st_ino}:{st.st_mtime_ns}"


@dataclass(frozen=True)
class ReferenceDelta:
    added: list[Key]
    removed: list[Key]
    prefetch: list[Key]  # most likely first


Box = Tuple[int, int, int, int]  # (i_min, i_max, j_min, j_max), inclusive


def box_minus(a: Box, b: Box) -> list[Box]:
    """``a`` without ``b``, as at most four disjoint boxes (the strips of ``a`` around ``b``)."""
    i0, i1, j0, j1 = max(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), min(a[3], b[3])
    if i0 > i1 or j0 > j1:
        return [a]
    strips = [(a[0], i0 - 1, a[2], a[3]), (i1 + 1, a[1], a[2], a[3]), (i0, i1, a[2], j0 - 1), (i0, i1, j1 + 1, a[3])]
    return [box for box in strips if box[0] <= box[1] and box[2] <= box[3]]


def open_store_directory(store: MapStore, grid_size: float | None = None) -> TileDirectory:
    """The tiles of a map store's index in use, from its cached copy of index.json."""
    return open_tile_directory(store.index_path().parent, grid_size)


class TileReferences:
    def __init__(self, directory: TileDirectory, store: MapStore | None = None) -> None:
        """``store``: the map store ``directory`` lists (open_store_directory), for a map given by URL."""
        self.directory = directory
        self.store = store
        self.location = store.url if store is not None else str(directory.path)  # what tile_delta names
        self.revision = self._current_revision()
        self._loaded: set[int] = set()  # codes (tiles.directory.encode_key) of the window's tiles
        self._box: Box | None = None  # the window they fill

    def _codes_in(self, boxes: Sequence[Box]) -> list[int]:
        return sorted(c for box in boxes for c in self.directory.codes_in_box(*box))

    def update(self, window: Window, ahead: Sequence[Window] = ()) -> ReferenceDelta:
        # A window moves by a strip at a time: only the strips between the old and the new box are listed,
        # not the whole window (about 2,600 tiles with the urban preset).
        box = window.bounds
        if self._box is None:
            added, removed = self._codes_in([box]), []
        else:
            added, removed = self._codes_in(box_minus(box, self._box)), self._codes_in(box_minus(self._box, box))
        self._loaded.difference_update(removed)
        self._loaded.update(added)
        self._box = box
        prefetch: list[int] = []
        named: set[int] = set()
        for w in ahead:  # most likely window first
            fresh = [c for c in self._codes_in(box_minus(w.bounds, box)) if c not in named]
            named.update(fresh)
            prefetch += fresh[: PREFETCH_MAX_TILES - len(prefetch)]
            if len(prefetch) == PREFETCH_MAX_TILES:
                break
        return ReferenceDelta(
            [decode_key(c) for c in added], [decode_key(c) for c in removed], [decode_key(c) for c in prefetch]
        )

    def loaded(self) -> list[Key]:
        return sorted(decode_key(c) for c in self._loaded)

    def paths(self) -> list[Path]:
        """Files of the window's tiles (map_cloud reads them when someone subscribes)."""
        return [self.directory.tile_path(k) for k in self.loaded()]

    def refresh(self) -> bool:
        """Reopens the directory when its index revision changed; True then (the window must be sent
        again as a reset). Raises UserError when the directory became unusable (the old one is kept)."""
        try:
            revision = self._current_revision()
        except OSError as err:
            raise UserError(
                f"tile directory {self.directory.path} cannot be read any more ({err.strerror});"
                " restore it or restart the provider with another tiles/dir"
            ) from None
        if revision == self.revision:
            return False
        self.directory = open_tile_directory(self.directory.path, self.directory.grid_size)
        self.revision = revision
        self._loaded = set()
        self._box = None
        return True

    def _current_revision(self) -> str:
        return self.store.revision if self.store is not None else index_revision(self.directory.path)
