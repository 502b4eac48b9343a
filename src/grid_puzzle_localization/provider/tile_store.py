"""The tiles currently loaded for the window, with a bounded cache that a background thread fills one
update ahead in the direction of travel (the paper's Algorithm 2, step 4, made incremental).

``TileStore.update(window, predicted)`` loads the tiles that entered the window (from the cache when
the prefetcher or an earlier window already read them), drops those that left (into the cache while it
has room, so a U-turn is served from memory) and returns the change. A tile that fails to read is
skipped, reported once in the returned delta, and listed in the stats for good. Thread-safe: one lock
guards all state; files are read outside it.

Memory: tiles are kept compact (x, y, z float32 by default, see tiles/reader.py), and the cache is
bounded by ``cache_mb``, by default an eighth of the loaded window (tiles read ahead are worth more
than tiles left behind: those only fill spare room and are evicted first).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.provider.window import Window
from grid_puzzle_localization.tiles.directory import TileDirectory, decode_key
from grid_puzzle_localization.tiles.reader import read_tile

Key = tuple[int, int]  # (i, j); internally tiles are keyed by their int64 code (tile_directory.encode_keys)
AUTO_CACHE_FRACTION = 0.125  # cache_mb = 0: the cache holds this fraction of the loaded window's bytes
AUTO_CACHE_MIN_BYTES = 2**20


@dataclass(frozen=True)
class StoreDelta:
    """What one update changed. ``added`` pairs each entering key with its points."""

    added: list[tuple[Key, np.ndarray]]
    removed: list[Key]
    newly_corrupt: list[tuple[Path, str]]  # (file, reason), each reported once
    load_ms: float  # wall time of the update [ms]
    hits: int  # entering tiles served from the cache
    misses: int  # entering tiles read from disk during the update


@dataclass
class StoreStats:
    tiles_loaded: int = 0
    points: int = 0
    bytes: int = 0
    cache_hits: int = 0
    cache_misses: int = 0
    cache_tiles: int = 0
    cache_bytes: int = 0
    prefetched: int = 0  # tiles read by the background thread
    corrupt: list[str] = field(default_factory=list)


class TileStore:
    def __init__(
        self, directory: TileDirectory, cache_mb: float = 0.0, prefetch: bool = True, xyz_only: bool = True
    ) -> None:
        """``cache_mb`` [MiB] bounds the cache; 0 (auto) bounds it by AUTO_CACHE_FRACTION of the bytes of
        the loaded window (at least 1 MiB): the tiles of the next window, and of a turn into a
        neighbouring sector as far as they fit. ``xyz_only``: keep only x, y, z as float32 (else every
        field of the tile files)."""
        self.directory = directory
        self._cache_mb = cache_mb
        self._xyz_only = xyz_only
        self._loaded_bytes = 0
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._loaded: dict[int, np.ndarray] = {}
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cache_bytes = 0
        self._corrupt: dict[int, str] = {}
        self._dtype: np.dtype | None = XYZ_DTYPE if xyz_only else None
        self._stats = StoreStats()
        self._pending: list[int] = []
        self._generation = 0
        self._in_flight: int | None = None
        self._busy = False  # the prefetcher is working through a request
        self._closed = False
        self._thread = None
        if prefetch:
            self._thread = threading.Thread(target=self._prefetch_loop, name="tile_prefetch", daemon=True)
            self._thread.start()

    # ------------------------------------------------------------ public API
    def update(self, window: Window, ahead: Sequence[Window] = ()) -> StoreDelta:
        """Makes the loaded set equal to the existing, readable tiles of ``window``; then asks the
        prefetcher for the tiles of the ``ahead`` windows (most likely first) that are not loaded."""
        start = time.perf_counter()
        wanted_codes = self.directory.codes_in(window)
        wanted = set(wanted_codes.tolist())
        with self._lock:
            removed = [c for c in self._loaded if c not in wanted]
            for code in removed:
                points = self._loaded.pop(code)
                self._loaded_bytes -= points.nbytes
                self._cache_put(code, points, spare_room_only=True)
            entering = [c for c in wanted_codes.tolist() if c not in self._loaded and c not in self._corrupt]
        added: list[tuple[Key, np.ndarray]] = []
        corrupt: list[tuple[Path, str]] = []
        hits = misses = 0
        for code in entering:
            points = self._take_cached(code)
            if points is not None:
                hits += 1
            else:
                misses += 1
                points, reason = self._read(code)
                if points is None:
                    with self._lock:
                        self._corrupt[code] = reason
                    corrupt.append((self._path(code), reason))
                    continue
            with self._lock:
                self._loaded[code] = points
                self._loaded_bytes += points.nbytes
                self._cache_drop(code)  # the prefetcher may have read it meanwhile
            added.append((decode_key(code), points))
        with self._lock:
            self._stats.cache_hits += hits
            self._stats.cache_misses += misses
            self._evict_to(self.cache_limit)  # the auto bound shrinks with the window
        if ahead:
            self._request_prefetch(ahead, wanted_codes)
        removed_keys = [decode_key(c) for c in removed]
        return StoreDelta(added, removed_keys, corrupt, (time.perf_counter() - start) * 1e3, hits, misses)

    @property
    def cache_limit(self) -> int:
        """Current bound of the cache [bytes]."""
        if self._cache_mb > 0.0:
            return int(self._cache_mb * 2**20)
        return max(int(self._loaded_bytes * AUTO_CACHE_FRACTION), AUTO_CACHE_MIN_BYTES)

    def loaded(self) -> list[tuple[Key, np.ndarray]]:
        """A snapshot of the loaded tiles, sorted by key."""
        with self._lock:
            return sorted((decode_key(c), p) for c, p in self._loaded.items())

    def point_arrays(self) -> list[np.ndarray]:
        """A snapshot of the loaded tiles' arrays (in no particular order; the arrays are never modified)."""
        with self._lock:
            return list(self._loaded.values())

    @property
    def dtype(self) -> np.dtype:
        """Point dtype of the tiles (XYZ_DTYPE when xyz_only or before any tile was read)."""
        return self._dtype if self._dtype is not None else XYZ_DTYPE

    def merged(self) -> np.ndarray:
        """All loaded points in one array (key order); empty with the tiles' dtype when none."""
        parts = [points for _, points in self.loaded()]
        return np.concatenate(parts) if parts else np.empty(0, dtype=self.dtype)

    def stats(self) -> StoreStats:
        with self._lock:
            s = self._stats
            s.tiles_loaded = len(self._loaded)
            s.points = sum(len(p) for p in self._loaded.values())
            s.bytes = self._loaded_bytes
            s.cache_tiles = len(self._cache)
            s.cache_bytes = self._cache_bytes
            s.corrupt = sorted(str(self._path(c)) for c in self._corrupt)
            return StoreStats(**vars(s))

    def wait_prefetch_idle(self, timeout: float | None = None) -> bool:
        """Blocks until the prefetcher has nothing left to do (tests and benchmarks use it to make the
        cache state deterministic); False on timeout."""
        with self._lock:
            return self._changed.wait_for(lambda: not self._pending and not self._busy, timeout)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._changed.notify_all()
        if self._thread is not None:
            self._thread.join()

    # ------------------------------------------------------------ internals
    def _path(self, code: int) -> Path:
        return self.directory.tile_path(decode_key(code))

    def _read(self, code: int) -> tuple[np.ndarray | None, str]:
        """Points of one tile, or (None, reason) when the file cannot be used."""
        path = self._path(code)
        try:
            points = read_tile(path, self._xyz_only)
        except (PcdError, OSError) as err:
            return None, str(err)
        with self._lock:
            if self._dtype is None:
                self._dtype = points.dtype
            elif points.dtype != self._dtype:
                return None, f"{path}: fields {points.dtype} differ from the other tiles' {self._dtype}"
        return points, ""

    def _take_cached(self, key: int) -> np.ndarray | None:
        """Pops ``key`` from the cache, waiting for the prefetcher if it is reading that very tile."""
        with self._lock:
            while self._in_flight == key:
                self._changed.wait()
            points = self._cache.get(key)
            self._cache_drop(key)
            return points

    def _cache_put(
        self, key: int, points: np.ndarray, protected: set[int] | None = None, spare_room_only: bool = False
    ) -> bool:
        """Inserts under the lock, evicting least recently used tiles; returns False (and keeps the cache)
        when that would evict a ``protected`` tile or the tile alone exceeds the limit. ``spare_room_only``
        (a tile that left the window): insert it only if nothing must be evicted, as the next to go."""
        self._cache_drop(key)
        limit = self.cache_limit
        if points.nbytes > limit:
            return False
        if spare_room_only:
            if self._cache_bytes + points.nbytes > limit:
                return False
            self._cache[key] = points
            self._cache.move_to_end(key, last=False)
            self._cache_bytes += points.nbytes
            return True
        while self._cache_bytes + points.nbytes > limit:
            oldest = next(iter(self._cache))
            if protected is not None and oldest in protected:
                return False
            self._cache_bytes -= self._cache.pop(oldest).nbytes
        self._cache[key] = points
        self._cache_bytes += points.nbytes
        return True

    def _evict_to(self, limit: int) -> None:
        while self._cache_bytes > limit:
            self._cache_bytes -= self._cache.popitem(last=False)[1].nbytes

    def _cache_drop(self, key: int) -> None:
        stale = self._cache.pop(key, None)
        if stale is not None:
            self._cache_bytes -= stale.nbytes

    def _request_prefetch(self, ahead: Sequence[Window], wanted: np.ndarray) -> None:
        codes = np.concatenate([self.directory.codes_in(w) for w in ahead])
        _, first = np.unique(codes, return_index=True)
        codes = codes[np.sort(first)]  # unique, most likely window first
        todo = codes[~np.isin(codes, wanted)].tolist()
        with self._lock:
            self._pending = [c for c in todo if c not in self._cache and c not in self._corrupt]
            self._generation += 1
            self._changed.notify_all()

    def _prefetch_loop(self) -> None:
        while True:
            with self._lock:
                while not self._pending and not self._closed:
                    self._changed.wait()
                if self._closed:
                    return
                todo, self._pending, generation = self._pending, [], self._generation
                self._busy = True
            try:
                self._prefetch(todo, generation)
            finally:
                with self._lock:
                    self._busy = False
                    self._changed.notify_all()

    def _prefetch(self, todo: list[int], generation: int) -> None:
        round_keys: set[int] = set()
        for key in todo:
            with self._lock:
                if self._closed or generation != self._generation:
                    break
                if key in self._loaded or key in self._cache or key in self._corrupt:
                    continue
                self._in_flight = key
            points, _ = self._read(key)  # a bad tile is reported when the window reaches it
            with self._lock:
                self._in_flight = None
                self._changed.notify_all()
                if points is None or key in self._loaded:
                    continue
                self._stats.prefetched += 1
                if not self._cache_put(key, points, protected=round_keys):
                    break
                round_keys.add(key)
