"""The grid puzzle search window (the paper's Eq. 2-5, Table I and Algorithm 2), with its two slips fixed.

The window is the set of tile indices ``(i, j) = (ci + u, cj + v)`` around the agent's tile
``(ci, cj) = (floor(ax / s), floor(ay / s))`` (Eq. 2: the centre ``c' = floor(a / s) * s + s / 2``), with

    u in [-n + du_min(theta), n + du_max(theta)],   v in [-n + dv_min(theta), n + dv_max(theta)]

(the paper prints ``u_min = n + du_min`` and ``v_max = -n + dv_max``; the intended (2n+1) x (2n+1)
default square needs ``-n`` for the minima and ``+n`` for the maxima). The heading ``theta`` is the
angle of the movement vector with ``atan2`` on the full circle (the paper's arccos cannot tell a move
up from a move down).

Table I sectors are half-open intervals ``[lo, hi)`` in degrees, after normalising the heading to
``[-20, 340)``: a heading exactly on a boundary belongs to the sector that *starts* there (20 deg is
sector 1, -20 deg = 340 deg is sector 0). Headings are compared in degrees rounded to 1e-9 deg, so
``math.radians(20)`` is on the boundary, not a rounding error below it.

Pure Python (no ROS, no numpy): the node and ``gpm window`` run this same code.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiles.grid import tile_index

# Sector boundaries [deg] inside the normalised range [-20, 340); sector m is [_BOUNDS[m], _BOUNDS[m + 1]).
SECTOR_BOUNDS_DEG: tuple[float, ...] = (-20.0, 20.0, 70.0, 110.0, 160.0, 200.0, 250.0, 290.0, 340.0)
# Table I: (du_min, du_max, dv_min, dv_max) in units of k, per sector.
SECTOR_DELTAS: tuple[tuple[int, int, int, int], ...] = (
    (0, 1, 0, 0),  # [-20, 20): +x
    (0, 1, 0, 1),  # [20, 70): +x +y
    (0, 0, 0, 1),  # [70, 110): +y
    (-1, 0, 0, 1),  # [110, 160): -x +y
    (-1, 0, 0, 0),  # [160, 200): -x
    (-1, 0, -1, 0),  # [200, 250): -x -y
    (0, 0, -1, 0),  # [250, 290): -y
    (0, 1, -1, 0),  # [290, 340): +x -y
)
NO_SECTOR = -1
HEADING_SOURCES = ("motion", "yaw")
# The paper's two experiments (n, k), both with s = 2 m.
PRESETS: dict[str, tuple[int, int]] = {"urban": (25, 20), "courtyard": (17, 10)}


@dataclass(frozen=True)
class WindowConfig:
    """Window parameters (the node's ``window/*`` parameters; config/grid_puzzle_map_provider.yaml
    documents them). Defaults are the paper's urban preset."""

    n: int = 25  # [tiles] half side of the default square: (2n+1) x (2n+1) tiles
    k: int = 20  # [tiles] extension toward the heading (Table I)
    update_distance: float = 0.0  # [m] recompute after moving farther than this; 0 -> s / 2 (the paper's step 5)
    heading_source: str = "motion"  # motion: direction of travel; yaw: the pose's orientation
    lookahead_time: float = 0.0  # [s] centre the window on position + velocity * lookahead_time
    preset: str = ""  # "urban" or "courtyard" sets n and k to the paper's values ("" = use n, k)

    def resolved(self) -> WindowConfig:
        """Checks the values and applies the preset; raises UserError naming the bad parameter."""
        n, k = self.n, self.k
        if self.preset:
            if self.preset not in PRESETS:
                raise UserError(f"window preset '{self.preset}' is unknown; use one of {sorted(PRESETS)} or ''")
            n, k = PRESETS[self.preset]
        if int(n) != n or n < 0 or int(k) != k or k < 0:
            raise UserError(f"window n and k must be integers >= 0 (got n={n}, k={k})")
        if self.heading_source not in HEADING_SOURCES:
            raise UserError(f"window heading_source '{self.heading_source}' is unknown; use one of {HEADING_SOURCES}")
        if not (math.isfinite(self.update_distance) and self.update_distance >= 0.0):
            raise UserError(f"window update_distance must be >= 0 m (got {self.update_distance}); 0 means s / 2")
        if not (math.isfinite(self.lookahead_time) and self.lookahead_time >= 0.0):
            raise UserError(f"window lookahead_time must be >= 0 s (got {self.lookahead_time})")
        return WindowConfig(int(n), int(k), self.update_distance, self.heading_source, self.lookahead_time, "")

    def update_distance_for(self, s: float) -> float:
        """The gating distance [m] for tile side ``s``."""
        return self.update_distance if self.update_distance > 0.0 else s / 2.0


@dataclass(frozen=True)
class Window:
    """A window in tile indices; bounds inclusive. ``theta`` [rad] is NaN and ``sector`` -1 when no
    heading was known (plain square)."""

    center: tuple[int, int]
    theta: float
    sector: int
    u_range: tuple[int, int]
    v_range: tuple[int, int]

    @property
    def i_min(self) -> int:
        return self.center[0] + self.u_range[0]

    @property
    def i_max(self) -> int:
        return self.center[0] + self.u_range[1]

    @property
    def j_min(self) -> int:
        return self.center[1] + self.v_range[0]

    @property
    def j_max(self) -> int:
        return self.center[1] + self.v_range[1]

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        return self.i_min, self.i_max, self.j_min, self.j_max

    def keys(self) -> list[tuple[int, int]]:
        """All (i, j) in the window, i-major."""
        return [(i, j) for i in range(self.i_min, self.i_max + 1) for j in range(self.j_min, self.j_max + 1)]


def sector_of_degrees(deg: float) -> int:
    """Table I sector 0..7 of a heading in degrees (any value; normalised to [-20, 340))."""
    d = (round(deg, 9) + 20.0) % 360.0 - 20.0
    return bisect.bisect_right(SECTOR_BOUNDS_DEG, d) - 1


def sector_mid_degrees(sector: int) -> float:
    """Middle of a Table I sector [deg]."""
    return (SECTOR_BOUNDS_DEG[sector] + SECTOR_BOUNDS_DEG[sector + 1]) / 2.0


def sector_of(theta: float) -> int:
    """Table I sector of a heading [rad]."""
    return sector_of_degrees(math.degrees(theta))


def compute_window(x: float, y: float, theta: float | None, s: float, n: int, k: int) -> Window:
    """The window for agent position (x, y) [m] and heading ``theta`` [rad] (None: plain square)."""
    center = (tile_index(x, s), tile_index(y, s))
    if theta is None or not math.isfinite(theta):
        return Window(center, math.nan, NO_SECTOR, (-n, n), (-n, n))
    sector = sector_of(theta)
    du_min, du_max, dv_min, dv_max = SECTOR_DELTAS[sector]
    return Window(center, theta, sector, (-n + du_min * k, n + du_max * k), (-n + dv_min * k, n + dv_max * k))


def window_covering(window: Window | None, x: float, y: float, half_side: float, s: float) -> Window:
    """The smallest window that holds ``window`` (when given) and every tile meeting the square of half side
    ``half_side`` [m] around (x, y) [m], centred on (x, y)'s tile, without a heading."""
    i0, i1 = tile_index(x - half_side, s), tile_index(x + half_side, s)
    j0, j1 = tile_index(y - half_side, s), tile_index(y + half_side, s)
    if window is not None:
        i0, i1 = min(i0, window.i_min), max(i1, window.i_max)
        j0, j1 = min(j0, window.j_min), max(j1, window.j_max)
    ci, cj = tile_index(x, s), tile_index(y, s)
    return Window((ci, cj), math.nan, NO_SECTOR, (i0 - ci, i1 - ci), (j0 - cj, j1 - cj))


@dataclass(frozen=True)
class PoseSample:
    """One pose in the map frame: position [m], time [s], optional yaw [rad] and velocity [m/s]."""

    x: float
    y: float
    t: float = 0.0
    yaw: float | None = None
    velocity: tuple[float, float] | None = None


class WindowTracker:
    """Algorithm 2's outer loop: decides when the window is recomputed and with which heading.

    The window is recomputed on the first pose and whenever the agent has moved farther than the
    update distance from the last update position. The heading is the direction of that movement
    (``motion``) or the pose's yaw (``yaw``, falling back to motion when a pose has no orientation).
    Between updates the last heading is kept; before any heading exists the window is the plain square.
    """

    def __init__(self, config: WindowConfig, s: float) -> None:
        self.config = config.resolved()
        self.s = s
        self.update_distance = self.config.update_distance_for(s)
        self._anchor: PoseSample | None = None
        self._theta: float | None = None
        self._center_point = (0.0, 0.0)  # [m] the point the window was last centred on
        self.window: Window | None = None
        self.last_step = 0.0  # [m] distance between the last two update positions

    def update(self, pose: PoseSample) -> Window | None:
        """Feeds one pose; returns the recomputed window, or None while the agent has not moved far enough."""
        anchor = self._anchor
        if anchor is not None:
            step = math.hypot(pose.x - anchor.x, pose.y - anchor.y)
            if not step > self.update_distance:
                return None
            self.last_step = step
            self._theta = math.atan2(pose.y - anchor.y, pose.x - anchor.x)
        if self.config.heading_source == "yaw" and pose.yaw is not None:
            self._theta = pose.yaw
        cx, cy = self._center_point = self.lookahead_point(pose, anchor)
        self._anchor = pose
        self.window = compute_window(cx, cy, self._theta, self.s, self.config.n, self.config.k)
        return self.window

    def restart(self) -> None:
        """The next pose recomputes the window wherever it is (the heading is kept), e.g. after a window that
        did not follow the pose."""
        self._anchor = None

    def lookahead_point(self, pose: PoseSample, anchor: PoseSample | None) -> tuple[float, float]:
        """Position the window is centred on: the pose, moved ahead by velocity * lookahead_time. The
        velocity is the pose's own when given, else the one between the last two update positions."""
        t = self.config.lookahead_time
        if t <= 0.0:
            return pose.x, pose.y
        velocity = pose.velocity
        if velocity is None and anchor is not None and pose.t > anchor.t:
            dt = pose.t - anchor.t
            velocity = ((pose.x - anchor.x) / dt, (pose.y - anchor.y) / dt)
        if velocity is None:
            return pose.x, pose.y
        return pose.x + velocity[0] * t, pose.y + velocity[1] * t

    def predicted_windows(self) -> list[Window]:
        """Windows one update ahead, most likely first: the last window centre moved along the heading
        by the last step (at least just over the update distance), keeping the heading, then turning
        into each neighbouring Table I sector (so a turn is served from the prefetch cache too). Empty
        before a heading exists."""
        if self._theta is None or self.window is None:
            return []
        step = max(self.last_step, self.update_distance) * 1.01
        x = self._center_point[0] + step * math.cos(self._theta)
        y = self._center_point[1] + step * math.sin(self._theta)
        n, k = self.config.n, self.config.k
        sector = sector_of(self._theta)
        headings = [self._theta] + [math.radians(sector_mid_degrees((sector + d) % 8)) for d in (1, -1)]
        return [compute_window(x, y, theta, self.s, n, k) for theta in headings]
