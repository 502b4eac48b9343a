"""A small structured world for localizer tests and benchmarks: a ground plane, walls, boxes and
poles, scanned analytically by an HDL-32E-like LiDAR along a smooth drive.

Everything is numpy and seeded; no ROS. Units: metres, seconds, radians. Frames: ``map`` (the world),
``base_link`` (the vehicle, x forward, z up) and ``lidar`` (mounted ``LIDAR_MOUNT`` above base_link).
The real simulator replaces this later; ray/box/cylinder intersection is enough for NDT.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# HDL-32E: 32 lasers from -30.67 deg to +10.67 deg, about 0.2 deg between firings at 10 Hz.
HDL32_ELEVATIONS_DEG = np.linspace(-30.67, 10.67, 32)
HDL32_AZIMUTH_STEP_DEG = 0.2
# base_link -> lidar: 1.8 m up, 0.3 m forward, yawed 0.05 rad so the mounting is not the identity.
LIDAR_MOUNT_XYZ = np.array([0.3, 0.0, 1.8])
LIDAR_MOUNT_YAW = 0.05


@dataclass(frozen=True)
class Scene:
    """Axis-aligned boxes ``(N, 2, 3)`` (min and max corner), vertical poles ``(M, 4)`` (x, y, radius,
    height) standing on the ground plane z = 0, and the ground extent ``(xmin, xmax, ymin, ymax)``."""

    boxes: np.ndarray
    poles: np.ndarray
    ground: tuple[float, float, float, float]


@dataclass(frozen=True)
class Drive:
    """A smooth drive along x with a gentle weave: position p(t) = (x0 + v t, a sin(w t), 0), heading
    along the velocity. ``rate`` [Hz] is the scan rate."""

    duration: float = 6.0
    rate: float = 10.0
    speed: float = 5.0
    x0: float = 0.0
    weave_amplitude: float = 3.0
    weave_omega: float = 0.35
    stamps: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = round(self.duration * self.rate)
        object.__setattr__(self, "stamps", np.arange(n) / self.rate)

    def pose(self, t: float) -> np.ndarray:
        """4x4 map_to_base at time ``t`` [s] from the start."""
        x = self.x0 + self.speed * t
        y = self.weave_amplitude * np.sin(self.weave_omega * t)
        dy = self.weave_amplitude * self.weave_omega * np.cos(self.weave_omega * t)
        yaw = np.arctan2(dy, self.speed)
        return pose_matrix(np.array([x, y, 0.0]), yaw)

    def angular_velocity(self, t: np.ndarray) -> np.ndarray:
        """Body angular velocity ``(len(t), 3)`` [rad/s] at times ``t`` [s], what a gyro on base_link reads
        (noise-free): the yaw rate d/dt atan(y'(t) / v) about z."""
        t = np.asarray(t, dtype=np.float64)
        a, w = self.weave_amplitude, self.weave_omega
        u = a * w * np.cos(w * t) / self.speed  # tan(yaw)
        du = -a * w * w * np.sin(w * t) / self.speed
        rates = np.zeros((t.size, 3))
        rates[:, 2] = du / (1.0 + u * u)
        return rates


def pose_matrix(xyz: np.ndarray, yaw: float) -> np.ndarray:
    """4x4 homogeneous transform: rotation ``yaw`` [rad] about z, then translation ``xyz`` [m]."""
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = xyz
    return m


def lidar_mount() -> np.ndarray:
    """4x4 base_T_lidar."""
    return pose_matrix(LIDAR_MOUNT_XYZ, LIDAR_MOUNT_YAW)


def make_scene(seed: int = 7, length: float = 160.0) -> Scene:
    """A street of ``length`` [m] along +x from x = -20: building blocks with gaps on both sides, parked
    boxes, poles at irregular spacing and a closing wall, so every degree of freedom is constrained."""
    rng = np.random.default_rng(seed)
    boxes = []
    for side in (-1.0, 1.0):
        x = -20.0
        while x < length:
            width = rng.uniform(8.0, 20.0)
            depth = rng.uniform(6.0, 12.0)
            near = rng.uniform(9.0, 13.0)
            height = rng.uniform(4.0, 15.0)
            y0, y1 = sorted((side * near, side * (near + depth)))
            boxes.append([[x, y0, 0.0], [x + width, y1, height]])
            x += width + rng.uniform(2.0, 6.0)
        # parked boxes (cars, containers) between the road and the buildings
        for bx in rng.uniform(-10.0, length - 10.0, size=12):
            y = side * rng.uniform(5.5, 7.5)
            size = rng.uniform([1.6, 1.6, 1.2], [4.5, 2.2, 2.6])
            boxes.append([[bx, y - size[1] / 2, 0.0], [bx + size[0], y + size[1] / 2, size[2]]])
    boxes.append([[length + 5.0, -25.0, 0.0], [length + 6.0, 25.0, 8.0]])
    boxes.append([[-26.0, -25.0, 0.0], [-25.0, 25.0, 8.0]])
    px = np.cumsum(rng.uniform(5.0, 11.0, size=40)) - 20.0
    px = px[px < length]
    py = np.where(np.arange(px.size) % 2 == 0, 1.0, -1.0) * rng.uniform(4.5, 5.2, size=px.size)
    poles = np.column_stack([px, py, rng.uniform(0.1, 0.25, size=px.size), rng.uniform(4.0, 8.0, size=px.size)])
    return Scene(boxes=np.array(boxes, dtype=np.float64), poles=poles, ground=(-30.0, length + 10.0, -30.0, 30.0))


def hdl32_directions() -> np.ndarray:
    """Unit ray directions ``(N, 3)`` in the lidar frame, ring-major."""
    el = np.deg2rad(HDL32_ELEVATIONS_DEG)[:, None]
    az = np.deg2rad(np.arange(0.0, 360.0, HDL32_AZIMUTH_STEP_DEG))[None, :]
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)
    return d.reshape(-1, 3)


def raycast(scene: Scene, origin: np.ndarray, dirs: np.ndarray, max_range: float) -> np.ndarray:
    """Distance [m] along each unit ray ``dirs`` from ``origin`` (map frame) to the first surface; inf on
    a miss or beyond ``max_range``."""
    t_best = np.full(dirs.shape[0], np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        # ground plane z = 0 inside its extent
        t = -origin[2] / dirs[:, 2]
        hit = origin[None, :2] + t[:, None] * dirs[:, :2]
        xmin, xmax, ymin, ymax = scene.ground
        ok = (t > 0) & (hit[:, 0] >= xmin) & (hit[:, 0] <= xmax) & (hit[:, 1] >= ymin) & (hit[:, 1] <= ymax)
        t_best = np.where(ok, t, t_best)
        inv = 1.0 / dirs
        # Surfaces farther than max_range cannot give a hit that is kept: skip them (same result, less work).
        box_distance = np.linalg.norm(np.clip(origin, scene.boxes[:, 0], scene.boxes[:, 1]) - origin, axis=1)
        for lo, hi in scene.boxes[box_distance <= max_range]:
            t1 = (lo - origin) * inv
            t2 = (hi - origin) * inv
            t_near = np.nanmax(np.minimum(t1, t2), axis=1)
            t_far = np.nanmin(np.maximum(t1, t2), axis=1)
            ok = (t_near <= t_far) & (t_near > 0) & (t_near < t_best)
            t_best = np.where(ok, t_near, t_best)
        dxy = dirs[:, :2]
        a = np.einsum("ij,ij->i", dxy, dxy)
        pole_distance = np.hypot(scene.poles[:, 0] - origin[0], scene.poles[:, 1] - origin[1]) - scene.poles[:, 2]
        for x, y, r, h in scene.poles[pole_distance <= max_range]:
            oc = origin[:2] - (x, y)
            b = dxy @ oc
            c = oc @ oc - r * r
            disc = b * b - a * c
            t = (-b - np.sqrt(disc)) / a
            z = origin[2] + t * dirs[:, 2]
            ok = (disc >= 0) & (t > 0) & (z >= 0) & (z <= h) & (t < t_best)
            t_best = np.where(ok, t, t_best)
    t_best[t_best > max_range] = np.inf
    return t_best


def scan(
    scene: Scene, map_to_base: np.ndarray, rng: np.random.Generator, noise: float = 0.01, max_range: float = 100.0
) -> np.ndarray:
    """One HDL-32E-like sweep from ``map_to_base`` (taken at one instant): points ``(K, 3)`` float32 in the
    lidar frame, misses dropped, with Gaussian range noise ``noise`` [m]."""
    map_to_lidar = map_to_base @ lidar_mount()
    dirs_lidar = hdl32_directions()
    dirs_map = dirs_lidar @ map_to_lidar[:3, :3].T
    ranges = raycast(scene, map_to_lidar[:3, 3], dirs_map, max_range)
    keep = np.isfinite(ranges)
    r = ranges[keep] + rng.normal(0.0, noise, size=int(keep.sum()))
    return (dirs_lidar[keep] * r[:, None]).astype(np.float32)


def _grid(a0: float, a1: float, b0: float, b1: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.meshgrid(np.arange(a0, a1 + 1e-9, step), np.arange(b0, b1 + 1e-9, step), indexing="ij")
    return a.ravel(), b.ravel()


def sample_map(scene: Scene, spacing: float = 0.25, noise: float = 0.01, seed: int = 11) -> np.ndarray:
    """The map: points ``(K, 3)`` float32 sampled every ``spacing`` [m] on every visible surface (ground,
    box sides and tops, pole mantles), with Gaussian noise ``noise`` [m]."""
    rng = np.random.default_rng(seed)
    parts = []
    xmin, xmax, ymin, ymax = scene.ground
    gx, gy = _grid(xmin, xmax, ymin, ymax, spacing)
    inside = np.zeros(gx.size, dtype=bool)
    for lo, hi in scene.boxes:
        inside |= (gx > lo[0]) & (gx < hi[0]) & (gy > lo[1]) & (gy < hi[1])
    parts.append(np.column_stack([gx[~inside], gy[~inside], np.zeros((~inside).sum())]))
    for lo, hi in scene.boxes:
        for axis in (0, 1):
            other = 1 - axis
            u, z = _grid(lo[other], hi[other], 0.0, hi[2], spacing)
            for value in (lo[axis], hi[axis]):
                face = np.empty((u.size, 3))
                face[:, axis], face[:, other], face[:, 2] = value, u, z
                parts.append(face)
        u, v = _grid(lo[0], hi[0], lo[1], hi[1], spacing)
        parts.append(np.column_stack([u, v, np.full(u.size, hi[2])]))
    for x, y, r, h in scene.poles:
        n_around = max(8, int(np.ceil(2 * np.pi * r / spacing)))
        ang, z = np.meshgrid(np.arange(n_around) * (2 * np.pi / n_around), np.arange(0.0, h, spacing), indexing="ij")
        ang, z = ang.ravel(), z.ravel()
        parts.append(np.column_stack([x + r * np.cos(ang), y + r * np.sin(ang), z]))
    points = np.concatenate(parts)
    points += rng.normal(0.0, noise, size=points.shape)
    return points.astype(np.float32)
