"""LiDAR beam patterns: when each ray of a sweep fires and where it points in the ``lidar`` frame.

- ``hdl32``: HDL-32E-like spinning sensor. 32 rings with elevations evenly spaced from -30.67 deg to
  +10.67 deg (ring 0 lowest), 10 Hz, 2170 firing columns per turn (46.08 us apart, 69,440 rays per
  sweep), the 32 lasers of a column 1.152 us apart; it turns clockwise seen from above, starting
  behind the sensor. Range 0.5-100 m. The pattern repeats every sweep.
- ``livox``: Livox Mid-360-like non-repetitive sensor. 200,000 rays/s (20,000 per 10 Hz frame), FoV
  360 deg x (-7 deg .. +52 deg). Directions follow the R2 low-discrepancy sequence (Roberts 2018)
  indexed by the global ray count, spread uniformly over the solid angle, so coverage keeps growing
  frame after frame instead of repeating; ``ring`` is the emitter (0-3, rays cycle through four).
  Range 0.1-70 m.

Both: Gaussian range noise (sigma 2 cm) and random dropouts (2 %); misses beyond the range are dropped.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from grid_puzzle_localization.errors import UserError

_PLASTIC = 1.324717957244746  # root of x^3 = x + 1; the R2 sequence steps by its inverse powers


@dataclass(frozen=True)
class Sweep:
    """One sweep's rays: time after the sweep start [s] (n,), unit directions in the lidar frame (n, 3)
    and the ring / emitter index (n,) uint16."""

    dt: np.ndarray
    directions: np.ndarray
    ring: np.ndarray


@dataclass(frozen=True)
class Lidar(ABC):
    """Common LiDAR parameters: sweep rate [Hz], ranges [m], range noise sigma [m], dropout probability."""

    name: str
    rate: float
    min_range: float
    max_range: float
    range_sigma: float
    dropout: float

    @property
    @abstractmethod
    def rays_per_sweep(self) -> int: ...

    @abstractmethod
    def sweep(self, index: int) -> Sweep:
        """The rays of sweep number ``index`` (0 for the first sweep of a run)."""


def _unit(azimuth: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    ce = np.cos(elevation)
    return np.stack([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)], axis=1)


def _fraction(x: np.ndarray) -> np.ndarray:
    """x mod 1 for non-negative x, in place (np.mod is an order of magnitude slower than floor)."""
    return np.subtract(x, np.floor(x), out=x)


@dataclass(frozen=True)
class SpinningLidar(Lidar):
    rings: int = 32
    elevation_min_deg: float = -30.67
    elevation_max_deg: float = 10.67
    columns: int = 2170
    laser_dt: float = 1.152e-6  # [s] between lasers of one firing column

    @property
    def rays_per_sweep(self) -> int:
        return self.rings * self.columns

    def elevations(self) -> np.ndarray:
        """Ring elevations [rad], ring 0 lowest."""
        return np.radians(np.linspace(self.elevation_min_deg, self.elevation_max_deg, self.rings))

    def sweep(self, index: int) -> Sweep:
        return self._pattern

    @cached_property
    def _pattern(self) -> Sweep:
        """The repeating sweep, computed once (callers must not modify its arrays)."""
        col = np.repeat(np.arange(self.columns), self.rings)
        ring = np.tile(np.arange(self.rings), self.columns)
        dt = col / (self.rate * self.columns) + ring * self.laser_dt
        azimuth = np.pi - 2 * np.pi * col / self.columns
        return Sweep(dt, _unit(azimuth, self.elevations()[ring]), ring.astype(np.uint16))


@dataclass(frozen=True)
class NonRepetitiveLidar(Lidar):
    rays_per_second: float = 200000.0
    elevation_min_deg: float = -7.0
    elevation_max_deg: float = 52.0
    emitters: int = 4

    @property
    def rays_per_sweep(self) -> int:
        return round(self.rays_per_second / self.rate)

    def sweep(self, index: int) -> Sweep:
        n = self.rays_per_sweep
        k = np.arange(n, dtype=np.float64) + float(index) * n
        u, v = _fraction(0.5 + k / _PLASTIC), _fraction(0.5 + k / _PLASTIC**2)
        lo, hi = np.sin(np.radians(self.elevation_min_deg)), np.sin(np.radians(self.elevation_max_deg))
        sin_el = lo + v * (hi - lo)  # uniform in sin(elevation): uniform over the solid angle
        cos_el = np.sqrt(1.0 - sin_el * sin_el)
        azimuth = 2 * np.pi * u
        directions = np.empty((n, 3), order="F")  # columns contiguous for the per-component maths
        np.multiply(cos_el, np.cos(azimuth), out=directions[:, 0])
        np.multiply(cos_el, np.sin(azimuth), out=directions[:, 1])
        directions[:, 2] = sin_el
        return Sweep(np.arange(n) / self.rays_per_second, directions, self._rings)

    @cached_property
    def _rings(self) -> np.ndarray:
        return (np.arange(self.rays_per_sweep) % self.emitters).astype(np.uint16)


SENSORS: dict[str, Lidar] = {
    "hdl32": SpinningLidar("hdl32", rate=10.0, min_range=0.5, max_range=100.0, range_sigma=0.02, dropout=0.02),
    "livox": NonRepetitiveLidar("livox", rate=10.0, min_range=0.1, max_range=70.0, range_sigma=0.02, dropout=0.02),
}
DEFAULT_SENSOR = {"courtyard": "livox", "urban": "hdl32", "corridor": "hdl32"}


def get_sensor(name: str) -> Lidar:
    if name not in SENSORS:
        raise UserError(f"unknown sensor {name!r}: choose one of {', '.join(SENSORS)}")
    return SENSORS[name]
