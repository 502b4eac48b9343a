"""Scans with poses, and keyframe selection by travelled distance."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Scan:
    """One LiDAR scan: its stamp [s], the robot pose ``T_map_robot`` (4x4) at that stamp, and a loader
    of its points ``(N, 3)`` [m] in the sensor frame. Points are loaded only for keyframes."""

    stamp: float
    pose: np.ndarray
    load_points: Callable[[], np.ndarray]


def select_keyframes(scans: Iterable[Scan], spacing: float) -> Iterator[Scan]:
    """Yields the first scan, then each scan whose robot position lies at least ``spacing`` metres from
    the previous keyframe's (``spacing == 0`` keeps every scan)."""
    last: np.ndarray | None = None
    for scan in scans:
        position = scan.pose[:3, 3]
        if last is None or np.linalg.norm(position - last) >= spacing:
            last = position
            yield scan
