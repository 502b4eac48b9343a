"""The window while the localizer is lost: it grows to hold the region the localizer's search covers and stops
following the pose (a prediction while lost) until the localizer tracks again.

Pure Python (no ROS): grid_puzzle_map_provider feeds it the localizer's status.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from grid_puzzle_localization.provider.window import Window, window_covering

SEARCH_STEP = 10.0  # [m] the window serving a search grows in steps of this (a delta every few scans, not each)


@dataclass(frozen=True)
class SearchRegion:
    """Where the lost localizer searches: centre [m] (map frame), radius [m], stamp [s]."""

    x: float
    y: float
    radius: float
    t: float


class LostSearchWindow:
    """Whether the window serves a search, and which window does: the union of the window the pose gave and the
    square of half side (search radius + ``reach``), rounded up to SEARCH_STEP and at most ``max_half_side``."""

    def __init__(self, max_half_side: float, reach: float, s: float) -> None:
        self.max_half_side = max_half_side  # [m]
        self.reach = reach  # [m] the pose's own window half side (n s): the scan's reach around the pose
        self.s = s
        self.active = False

    def cover(self, region: SearchRegion, pose_window: Window | None, served: Window | None) -> Window | None:
        """The window for ``region``, or None when it is ``served`` already; once one is returned the window serves
        the search."""
        half_side = min(math.ceil((region.radius + self.reach) / SEARCH_STEP) * SEARCH_STEP, self.max_half_side)
        window = window_covering(pose_window, region.x, region.y, half_side, self.s)
        if served is not None and window.bounds == served.bounds:
            return None
        self.active = True
        return window

    def end(self) -> bool:
        """The localizer tracks again; True when a search's window was being served (the pose takes over)."""
        was, self.active = self.active, False
        return was


HINT_SIGMAS = 3.0  # a hint's search region reaches this many standard deviations of its position


def hint_region(x: float, y: float, variance_x: float, variance_y: float, t: float) -> SearchRegion:
    """The search region of a coarse position (``initialpose_hint``): HINT_SIGMAS standard deviations of the larger of
    its variances [m^2] around it (radius 0 when they are not finite and positive). Raises ValueError for a position
    that is not finite."""
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"its position ({x}, {y}) is not finite")
    variance = max(variance_x, variance_y)
    radius = HINT_SIGMAS * math.sqrt(variance) if math.isfinite(variance) and variance > 0.0 else 0.0
    return SearchRegion(x, y, radius, t)
