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
from grid_puzzle_localization.sim.trajectory import Trajectory, rotate

# PointCloud2 layout of the ``points`` topic (packed, 22 bytes): time is seconds after header.stamp.
POINT_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f4")]
)


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
        """Map-frame origins (k, 3) and unit directions (k, 3) of rays fired at times ``t`` [s] along
        ``directions`` (k, 3) given in the lidar frame."""
        p, q = trajectory.interpolate(t)
        origin = p + rotate(q, self._mount.translation)
        return origin, rotate(q, directions @ self._mount.rotation.T)

    def simulate(
        self, trajectory: Trajectory, t_start: float, sweep: Sweep, rng: np.random.Generator, movers: Mesh | None = None
    ) -> np.ndarray:
        """Points (POINT_DTYPE, lidar frame) of ``sweep`` starting at ``t_start`` [s] on ``trajectory``;
        rays with no return (miss, out of range, dropout) are left out. ``movers`` are extra (moving)
        objects frozen for this sweep."""
        origin, world_dir = self.rays(trajectory, t_start + sweep.dt, sweep.directions)
        dist, prim = self._caster.cast(origin, world_dir)
        reflectivity, normals = self._reflectivity, self._normals
        if movers is not None:
            with RayCaster(movers, threads=self._caster.threads) as caster:
                d_mov, p_mov = caster.cast(origin, world_dir)
            closer = d_mov < dist
            dist = np.where(closer, d_mov, dist)
            prim = np.where(closer, p_mov + len(reflectivity), prim)
            reflectivity = np.concatenate([reflectivity, movers.reflectivity])
            normals = np.concatenate([normals, movers.face_normals()])
        s = self.sensor
        noise = rng.standard_normal(len(dist))
        keep = rng.random(len(dist)) >= s.dropout
        keep &= (dist >= s.min_range) & (dist <= s.max_range)
        r = dist[keep].astype(np.float64) + s.range_sigma * noise[keep]
        hit = prim[keep]
        cos_inc = np.abs(np.sum(normals[hit] * world_dir[keep], axis=1))
        out = np.empty(int(keep.sum()), dtype=POINT_DTYPE)
        xyz = sweep.directions[keep] * r[:, None]
        out["x"], out["y"], out["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        out["intensity"] = np.clip(255.0 * reflectivity[hit] * (0.3 + 0.7 * cos_inc), 0.0, 255.0)
        out["ring"] = sweep.ring[keep]
        out["time"] = sweep.dt[keep]
        return out
