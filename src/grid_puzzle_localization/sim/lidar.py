"""Simulated LiDAR sweeps with faithful motion distortion.

Every ray is cast from the sensor pose at that ray's own firing time (the trajectory interpolated per
ray), and the hit is reported in the ``lidar`` frame of that same instant, as a real sensor does; a
deskewing step can therefore recover the undistorted cloud from the per-point ``time`` field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.sim.meshes import Mesh
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.sensors import Lidar, Sweep
from grid_puzzle_localization.sim.trajectory import Trajectory, transform

# PointCloud2 layout of the ``points`` topic (packed, 22 bytes): time is seconds after header.stamp.
POINT_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f4")]
)


# Azimuth bins of the mover cull: 0.09 deg, far finer than a mover's angular size.
_AZIMUTH_BINS = 4096


def _may_hit(origin: np.ndarray, direction: np.ndarray, mesh: Mesh) -> np.ndarray:
    """Indices of the rays that can hit ``mesh`` (a few small movers), so only those are cast against it.

    Conservative: a ray from ``o`` hits a point ``p`` only along the azimuth of ``p - o``. With every
    origin within ``spread`` of the origins' centre ``c`` and every point of a triangle within ``rho`` of
    its centre ``m``, that azimuth is within asin((rho + spread) / |m - c|) of the azimuth of ``m - c``.
    Rays are binned by azimuth (float32 rounding is covered by one extra bin either side); if any
    triangle is that close to the origins, every ray is a candidate."""
    # Column by column: numpy's axis-0 reduction of an (n, 2) view is some 20 times slower.
    lo = np.array([float(origin[:, a].min()) for a in (0, 1)])
    hi = np.array([float(origin[:, a].max()) for a in (0, 1)])
    centre, spread = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    tri = mesh.triangles[:, :, :2].astype(np.float64)
    mid = tri.mean(axis=1)
    reach = np.linalg.norm(tri - mid[:, None], axis=2).max(axis=1) + spread + 1e-3
    to_mid = mid - centre
    dist = np.hypot(to_mid[:, 0], to_mid[:, 1])
    if np.any(dist <= reach):
        return np.arange(len(origin))
    scale = _AZIMUTH_BINS / (2 * np.pi)
    heading = np.arctan2(to_mid[:, 1], to_mid[:, 0]) + np.pi
    half = np.arcsin(reach / dist)
    first = np.floor((heading - half) * scale).astype(np.intp) - 1
    last = np.floor((heading + half) * scale).astype(np.intp) + 1
    edges = np.zeros(_AZIMUTH_BINS + 1, dtype=np.intp)  # +1 where an interval starts, -1 after it ends
    a, b = first % _AZIMUTH_BINS, last % _AZIMUTH_BINS
    wraps = a > b
    np.add.at(edges, a, 1)
    np.add.at(edges, b + 1, -1)
    np.add.at(edges, np.zeros(int(wraps.sum()), dtype=np.intp), 1)  # wrapped: [a, end) and [0, b]
    np.add.at(edges, np.full(int(wraps.sum()), _AZIMUTH_BINS, dtype=np.intp), -1)
    covered = np.cumsum(edges[:-1]) > 0
    azimuth = np.arctan2(direction[:, 1], direction[:, 0]) + np.float32(np.pi)
    bins = np.minimum((azimuth * np.float32(scale)).astype(np.intp), _AZIMUTH_BINS - 1)
    return np.flatnonzero(covered[bins])


@dataclass(frozen=True)
class Mount:
    """Pose of the lidar frame in base_link: ``translation`` (3,) [m], ``rotation`` (3, 3)."""

    translation: np.ndarray
    rotation: np.ndarray


class SweepSimulator:
    """Casts sweeps of ``sensor`` mounted at ``mount`` on a platform moving along a trajectory."""

    def __init__(self, mesh: Mesh, caster: RayCaster, sensor: Lidar, mount: Mount) -> None:
        self._caster = caster
        self._reflectivity = mesh.reflectivity
        self._normals = mesh.face_normals()
        self.sensor = sensor
        self._mount = mount

    def rays(self, trajectory: Trajectory, t: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame origins (k, 3) and unit directions (k, 3) (float32, as Embree takes them) of rays
        fired at times ``t`` [s] along ``directions`` (k, 3) given in the lidar frame."""
        pos, rot = trajectory.frames(t)
        n = len(pos[0])
        origin = transform(rot, self._mount.translation, pos, np.empty((n, 3), dtype=np.float32))
        base = (self._mount.rotation @ directions.T).astype(np.float32)  # (3, k) in base_link
        return origin, transform(rot, base, out=np.empty((n, 3), dtype=np.float32))

    def simulate(
        self, trajectory: Trajectory, t_start: float, sweep: Sweep, rng: np.random.Generator, movers: Mesh | None = None
    ) -> np.ndarray:
        """Points (POINT_DTYPE, lidar frame) of ``sweep`` starting at ``t_start`` [s] on ``trajectory``;
        rays with no return (miss, out of range, dropout) are left out. ``movers`` are extra (moving)
        objects frozen for this sweep."""
        origin, world_dir = self.rays(trajectory, t_start + sweep.dt, sweep.directions)
        dist, prim = self._caster.cast(origin, world_dir)
        mover_rays, mover_prims = np.empty(0, np.intp), np.empty(0, np.int32)
        if movers is not None:
            candidates = _may_hit(origin, world_dir, movers)
            if len(candidates):
                with RayCaster(movers, threads=1) as caster:
                    d_mov, p_mov = caster.cast(origin[candidates], world_dir[candidates])
                closer = d_mov < dist[candidates]
                mover_rays, mover_prims = candidates[closer], p_mov[closer]
                dist[mover_rays] = d_mov[closer]
        s = self.sensor
        n = len(dist)
        noise = rng.standard_normal(n, dtype=np.float32)
        keep = rng.random(n, dtype=np.float32) >= np.float32(s.dropout)
        keep &= (dist >= np.float32(s.min_range)) & (dist <= np.float32(s.max_range))
        idx = np.flatnonzero(keep)
        r = dist[idx] + np.float32(s.range_sigma) * noise[idx]
        hit = prim[idx]
        normal, reflectivity = self._normals[hit], self._reflectivity[hit]
        if len(mover_rays):  # kept rays whose return is a mover take its triangle's attributes
            on_mover = np.full(n, -1, dtype=np.int32)
            on_mover[mover_rays] = mover_prims
            kept_prims = on_mover[idx]
            at = np.flatnonzero(kept_prims >= 0)
            normal[at] = movers.face_normals()[kept_prims[at]]
            reflectivity[at] = movers.reflectivity[kept_prims[at]]
        cos_inc = np.abs(np.einsum("ij,ij->i", normal, world_dir[idx]))
        out = np.empty(len(idx), dtype=POINT_DTYPE)
        lidar_dir = sweep.directions[idx]
        for a, name in enumerate("xyz"):
            np.multiply(lidar_dir[:, a], r, out=out[name], casting="same_kind")
        out["intensity"] = np.clip(np.float32(255.0) * reflectivity * (0.3 + 0.7 * cos_inc), 0.0, 255.0)
        out["ring"] = sweep.ring[idx]
        out["time"] = sweep.dt[idx]
        return out
