"""What the provider serves: the window that follows the pose, or while the localizer is lost the window that holds
its search, and that window's tiles by reference. The provider node feeds it poses, search regions and the end of a
search, and publishes what it returns; the provider nodelet's WindowServer (provider/window_server.hpp) is its C++
twin, held equal to it by test_window_server_equality.

Pure Python (no ROS); not thread-safe (the node serialises its calls).
"""

from __future__ import annotations

from dataclasses import dataclass

from grid_puzzle_localization.provider.lost_search import LostSearchWindow, SearchRegion
from grid_puzzle_localization.provider.tile_references import ReferenceDelta, TileReferences
from grid_puzzle_localization.provider.window import PoseSample, Window, WindowTracker, window_covering
from grid_puzzle_localization.tiles.directory import Key


def nearest_first(keys: list[Key], x: float, y: float, s: float) -> list[Key]:
    """``keys`` sorted by the distance of their tile's centre from (x, y) [m], nearest first, ties in (i, j) order:
    the localizer loads a delta's tiles in its order, so the tiles under the scan arrive first. Tile side ``s`` [m].
    The twin of window_server.hpp's sortNearestFirst (the same arithmetic, so both give the same order)."""

    def distance2(key: Key) -> float:
        dx = (key[0] + 0.5) * s - x
        dy = (key[1] + 0.5) * s - y
        return dx * dx + dy * dy

    return sorted(keys, key=lambda k: (distance2(k), k[0], k[1]))


@dataclass(frozen=True)
class Served:
    """One window update: the window, its tile change, and where it was computed."""

    window: Window
    delta: ReferenceDelta
    first: bool  # the first window since the start or a refresh of the directory: sent as a reset
    changed: bool  # the tile set or the bounds changed: a new delta revision is due
    pose: PoseSample  # the pose, or the search region's centre, the window was computed for


class WindowServer:
    def __init__(self, tracker: WindowTracker, tiles: TileReferences, max_half_side: float) -> None:
        self.tracker = tracker
        self.tiles = tiles
        self.lost = LostSearchWindow(max_half_side, tracker.config.n * tracker.s, tracker.s)
        self.window: Window | None = None  # the window served last
        self.focus = PoseSample(0.0, 0.0, 0.0)  # the pose or search centre it was served for: nearest tiles go first

    def end_search(self) -> None:
        """The localizer tracks again: the next pose recomputes the window wherever it is."""
        if self.lost.end():
            self.tracker.restart()

    def on_search(self, region: SearchRegion) -> Served | None:
        """The window holding the lost localizer's search region, or None when it is served already."""
        window = self.lost.cover(region, self.tracker.window, self.window)
        return None if window is None else self._serve(PoseSample(region.x, region.y, region.t), window)

    def on_whole_map(self, t: float = 0.0) -> Served | None:
        """Every tile of the directory, for the global search of a start without a pose or a hint, or None when it is
        served already (or the directory is empty). Like a search's window it stays until the localizer tracks."""
        i0, i1, j0, j1 = self.tiles.directory.bounds
        if i0 > i1 or j0 > j1:
            return None
        s = self.tracker.s
        x, y = (i0 + i1 + 1) * s / 2, (j0 + j1 + 1) * s / 2
        window = window_covering(None, x, y, max(i1 - i0 + 1, j1 - j0 + 1) * s / 2, s)
        if self.window is not None and window.bounds == self.window.bounds:
            return None
        self.lost.active = True
        return self._serve(PoseSample(x, y, t), window)

    def map_extent(self) -> tuple[float, float, float, float]:
        """[m] x_min, x_max, y_min, y_max of the box of the directory's tiles."""
        i0, i1, j0, j1 = self.tiles.directory.bounds
        s = self.tracker.s
        return i0 * s, (i1 + 1) * s, j0 * s, (j1 + 1) * s

    def touches_map(self, region: SearchRegion) -> bool:
        """True when the square of half side ``region.radius`` around its centre meets the directory's tiles' box."""
        x0, x1, y0, y1 = self.map_extent()
        r = region.radius
        return x0 <= region.x + r and region.x - r <= x1 and y0 <= region.y + r and region.y - r <= y1

    def map_area(self) -> float:
        """[m^2] of the directory's bounding box of tiles."""
        i0, i1, j0, j1 = self.tiles.directory.bounds
        return max(0, i1 - i0 + 1) * max(0, j1 - j0 + 1) * self.tracker.s**2

    def on_pose(self, pose: PoseSample) -> Served | None:
        """The window after ``pose``, or None when it stays (not moved far enough, or a search's window is served:
        while the localizer is lost its pose is a prediction)."""
        if self.lost.active:
            return None
        window = self.tracker.update(pose)
        return None if window is None else self._serve(pose, window)

    def refresh(self) -> bool:
        """True when the tile directory was rewritten (a new index revision): the whole window is due as a reset."""
        return self.tiles.refresh()

    def whole(self) -> tuple[Window, ReferenceDelta] | None:
        """The served window with all its tiles as ``added`` (a reset), or None before the first window."""
        if self.window is None:
            return None
        # Changes nothing, except after a refresh, which emptied the set: then it loads the new directory's.
        prefetch = self.tiles.update(self.window, self.tracker.predicted_windows()).prefetch
        added = nearest_first(self.tiles.loaded(), self.focus.x, self.focus.y, self.tracker.s)
        return self.window, ReferenceDelta(added, [], prefetch)

    def _serve(self, pose: PoseSample, window: Window) -> Served:
        delta = self.tiles.update(window, self.tracker.predicted_windows())
        added = nearest_first(delta.added, pose.x, pose.y, self.tracker.s)
        delta = ReferenceDelta(added, delta.removed, delta.prefetch)
        first = self.window is None
        changed = first or bool(delta.added or delta.removed) or window.bounds != self.window.bounds
        self.window = window
        self.focus = pose
        return Served(window, delta, first, changed, pose)
