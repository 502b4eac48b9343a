"""Smooth platform trajectories along a world's path network.

A route is a random walk over the path graph that prefers unvisited edges and never turns back, so it
turns left and right, crosses diagonals and revisits places. The lane (``lane_offset`` metres right of
the centre line) gets circular corners of ``corner_radius``; the speed follows the curvature limit
sqrt(lat_accel / kappa), stops before some crossings, and respects acceleration limits. The cruise
speed is tuned so the average speed, stops included, matches ``speed_avg``. Positions and yaw are
finally low-pass filtered (Gaussian, ``smooth_sigma`` seconds) so velocity, acceleration and yaw rate
are continuous, which the IMU model differentiates.

Poses are sampled at ``RATE`` Hz: ``base_link`` sits on the terrain, its z axis along the terrain
normal and its x axis along the heading. Times are seconds from the start of the trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.sim.layout import PathGraph
from grid_puzzle_localization.sim.worlds import Ground, World

RATE = 200.0  # [Hz] pose sampling rate (also the IMU rate)
_GEOM_STEP = 0.05  # [m] spacing of the dense lane curve
REST = 2.0  # [s] standing still at the start (lets an IMU initialise) and at the end


@dataclass(frozen=True)
class MotionProfile:
    """How a platform moves. Lengths [m], speeds [m/s], accelerations [m/s^2], times [s]."""

    length: float  # full-scale route length
    speed_avg: float  # average speed including stops
    corner_radius: float
    lane_offset: float  # right of the path centre line
    accel: float
    decel: float
    lat_accel: float
    stop_prob: float  # probability of a stop before a route node
    stop_time: tuple[float, float]
    stop_backoff: float  # stop this far before the corner
    speed_step: float  # arc-length step of the speed profile
    smooth_sigma: float
    # Traffic: the cruise speed dips by up to this fraction, as a cosine of the arc length with this wavelength.
    cruise_dip: float = 0.0
    dip_wavelength: float = 150.0


PROFILES: dict[str, MotionProfile] = {
    # A person walking with a backpack LiDAR: ~0.65 km at ~0.51 m/s (~1270 s), short pauses.
    "courtyard": MotionProfile(650.0, 0.512, 1.5, 0.6, 0.5, 0.7, 0.4, 0.08, (2.0, 6.0), 0.0, 0.1, 0.25),
    # A car in traffic: ~3.6 km at ~4.6 m/s average (~785 s), stops at some crossings.
    "urban": MotionProfile(3600.0, 4.6, 9.0, 2.5, 1.5, 2.5, 2.0, 0.3, (3.0, 15.0), 8.0, 0.25, 0.2),
    # A car through a road tunnel in traffic: ~1 km at ~11 m/s average, between about 10 and 15 m/s, no stops.
    "corridor": MotionProfile(1000.0, 11.0, 9.0, 2.0, 1.5, 2.5, 2.0, 0.0, (3.0, 15.0), 0.0, 0.25, 0.2, 0.33, 150.0),
}


@dataclass(frozen=True)
class Trajectory:
    """Poses of ``base_link`` in ``map`` sampled every 1 / RATE s from t = 0: ``position`` (n, 3) [m],
    ``quat`` (n, 4) x y z w (sign-continuous) and the route node sequence it follows."""

    position: np.ndarray
    quat: np.ndarray
    route: np.ndarray

    @property
    def times(self) -> np.ndarray:
        return np.arange(len(self.position)) / RATE

    @property
    def duration(self) -> float:
        return (len(self.position) - 1) / RATE

    def length(self) -> float:
        """Horizontal path length [m]."""
        return float(np.linalg.norm(np.diff(self.position[:, :2], axis=0), axis=1).sum())

    def yaw(self) -> np.ndarray:
        """Heading of base_link's x axis in the map plane [rad], in (-pi, pi]."""
        return Rotation.from_quat(self.quat).as_euler("ZYX")[:, 0]

    def truncated(self, duration: float) -> Trajectory:
        n = min(len(self.position), int(np.floor(duration * RATE + 1e-9)) + 1)
        return Trajectory(self.position[:n], self.quat[:n], self.route)

    def interpolate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (k, 3) and unit quaternions (k, 4) x y z w at times ``t`` [s] (clamped to the
        trajectory): linear in position, normalised linear in quaternion (exact enough at 200 Hz)."""
        f = np.clip(np.asarray(t, dtype=np.float64) * RATE, 0.0, len(self.position) - 1.0)
        i = np.minimum(f.astype(np.int64), len(self.position) - 2)
        w = (f - i)[:, None]
        pos = self.position[i] * (1 - w) + self.position[i + 1] * w
        q = self.quat[i] * (1 - w) + self.quat[i + 1] * w
        return pos, q / np.linalg.norm(q, axis=1, keepdims=True)

    @cached_property
    def _knots(self) -> tuple[np.ndarray, ...]:
        """Component-major samples and their increments to the next sample, for :meth:`frames`."""
        p, q = np.ascontiguousarray(self.position.T), np.ascontiguousarray(self.quat.T, dtype=np.float32)
        return p, np.diff(p, axis=1), q, np.diff(q, axis=1)

    def frames(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (3, k) [m] and rotation matrices (3, 3, k) (float32, map from base_link) at times
        ``t`` [s]: the interpolation of :meth:`interpolate`, laid out component-major so that per-ray
        poses cost a few passes over contiguous arrays (see :func:`transform`)."""
        p0, dp, q0, dq = self._knots
        f = np.clip(np.asarray(t, dtype=np.float64) * RATE, 0.0, len(self.position) - 1.0)
        i = np.minimum(f.astype(np.intp), len(self.position) - 2)
        w = f - i
        pos = np.take(p0, i, axis=1) + w * np.take(dp, i, axis=1)
        q = np.take(q0, i, axis=1) + w.astype(np.float32) * np.take(dq, i, axis=1)
        x, y, z, qw = q
        s = np.float32(2.0) / np.einsum("ij,ij->j", q, q)  # normalises the interpolated quaternion
        xs, ys, zs = x * s, y * s, z * s
        xx, yy, zz, xy, xz, yz = x * xs, y * ys, z * zs, x * ys, x * zs, y * zs
        wx, wy, wz = qw * xs, qw * ys, qw * zs
        one = np.float32(1.0)
        rot = np.empty((3, 3, len(w)), dtype=np.float32)
        rot[0, 0], rot[0, 1], rot[0, 2] = one - (yy + zz), xy - wz, xz + wy
        rot[1, 0], rot[1, 1], rot[1, 2] = xy + wz, one - (xx + zz), yz - wx
        rot[2, 0], rot[2, 1], rot[2, 2] = xz - wy, yz + wx, one - (xx + yy)
        return pos, rot


def transform(rot: np.ndarray, v: np.ndarray, offset: np.ndarray | None = None, out: np.ndarray | None = None):
    """``rot @ v (+ offset)`` per column: ``rot`` (3, 3, k), ``v`` (3, k) or a constant (3,), ``offset``
    (3, k) or None. Writes into ``out`` (k, 3) when given (any float dtype), else returns (3, k)."""
    v = np.asarray(v)
    col = v if v.ndim == 2 else v.reshape(3, 1)
    res = out.T if out is not None else np.empty((3, rot.shape[2]), dtype=np.result_type(rot, col))
    for a in range(3):
        acc = rot[a, 0] * col[0]
        acc += rot[a, 1] * col[1]
        acc += rot[a, 2] * col[2]
        if offset is not None:
            np.add(offset[a], acc, out=res[a], casting="same_kind")
        else:
            res[a] = acc
    return res if out is None else out


def plan_route(graph: PathGraph, length: float, rng: np.random.Generator) -> list[int]:
    """Random walk over ``graph`` somewhat longer than ``length`` metres, preferring unvisited edges
    and never reversing onto the edge it came from (unless at a dead end)."""
    node = int(rng.integers(len(graph.nodes)))
    route, visits = [node], np.zeros(len(graph.edges))
    prev, travelled = -1, 0.0
    # Rounded corners make the lane shorter than the node polyline: overshoot, the caller cuts it.
    while travelled < 1.1 * length + 30.0 or len(route) < 3:
        options = [(e, b) for e, b in graph.neighbours(node) if b != prev] or graph.neighbours(node)
        weights = np.array([4.0 if visits[e] == 0 else 1.0 for e, _ in options])
        e, nxt = options[rng.choice(len(options), p=weights / weights.sum())]
        visits[e] += 1
        travelled += float(np.linalg.norm(graph.nodes[nxt] - graph.nodes[node]))
        route.append(nxt)
        prev, node = node, nxt
    return route


def _offset_polyline(p: np.ndarray, offset: float) -> np.ndarray:
    """Shifts a polyline ``offset`` metres to the right of its direction, with mitred corners."""
    d = np.diff(p, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    right = np.stack([d[:, 1], -d[:, 0]], axis=1)
    out = np.empty_like(p)
    out[0], out[-1] = p[0] + offset * right[0], p[-1] + offset * right[-1]
    a, b = right[:-1], right[1:]
    miter = (a + b) / (1.0 + np.sum(a * b, axis=1, keepdims=True))
    out[1:-1] = p[1:-1] + offset * miter
    return out


def _rounded_curve(p: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Dense curve (every ~5 cm) through polyline ``p`` with circular corners of ``radius`` (reduced on
    short segments). Returns points (n, 2), heading [rad, unwrapped] (n,), |curvature| [1/m] (n,), and
    the arc length of each corner's start (len(p) - 2,)."""
    d = np.diff(p, axis=0)
    seg = np.linalg.norm(d, axis=1)
    u = d / seg[:, None]
    pts, head, curv, corner_s = [], [], [], []
    s_total = 0.0
    start = p[0]

    def straight(a, b, direction):
        nonlocal s_total
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / _GEOM_STEP)))
        f = np.arange(n)[:, None] / n
        pts.append(a + f * (b - a))
        head.append(np.full(n, np.arctan2(direction[1], direction[0])))
        curv.append(np.zeros(n))
        s_total += float(np.linalg.norm(b - a))

    for i in range(1, len(p) - 1):
        din, dout = u[i - 1], u[i]
        cross = din[0] * dout[1] - din[1] * dout[0]
        theta = float(np.arccos(np.clip(np.dot(din, dout), -1.0, 1.0)))
        tan_half = np.tan(theta / 2)
        tangent = min(radius * tan_half, 0.45 * seg[i - 1], 0.45 * seg[i])
        a = p[i] - din * tangent
        straight(start, a, din)
        corner_s.append(s_total)
        if theta > 1e-6:
            r = tangent / tan_half
            side = 1.0 if cross > 0 else -1.0
            centre = a + side * r * np.array([-din[1], din[0]])
            h0 = np.arctan2(din[1], din[0])
            n = max(1, int(np.ceil(r * theta / _GEOM_STEP)))
            h = h0 + side * theta * np.arange(n) / n
            pts.append(centre + side * r * np.stack([np.sin(h), -np.cos(h)], axis=1))
            head.append(h)
            curv.append(np.full(n, 1.0 / r))
            s_total += r * theta
        start = p[i] + dout * tangent
    straight(start, p[-1], u[-1])
    pts.append(p[-1][None])
    head.append(np.array([np.arctan2(u[-1][1], u[-1][0])]))
    curv.append(np.zeros(1))
    return np.concatenate(pts), np.unwrap(np.concatenate(head)), np.concatenate(curv), np.array(corner_s)


def _speed_profile(kappa: np.ndarray, stops: np.ndarray, cruise: float, prof: MotionProfile) -> np.ndarray:
    """Speed [m/s] at samples ``prof.speed_step`` apart: curvature and stop limits, then acceleration
    limits forwards and decelerations backwards; zero at both ends."""
    dip = (
        prof.cruise_dip
        * 0.5
        * (1.0 - np.cos(2 * np.pi * np.arange(len(kappa)) * prof.speed_step / prof.dip_wavelength))
    )
    v = np.minimum(cruise * (1.0 - dip), np.sqrt(prof.lat_accel / np.maximum(kappa, 1e-9)))
    v[stops] = 0.0
    v[0] = v[-1] = 0.0
    two_a, two_d = 2 * prof.accel * prof.speed_step, 2 * prof.decel * prof.speed_step
    vv = v.tolist()
    for i in range(1, len(vv)):
        vv[i] = min(vv[i], (vv[i - 1] ** 2 + two_a) ** 0.5)
    for i in range(len(vv) - 2, -1, -1):
        vv[i] = min(vv[i], (vv[i + 1] ** 2 + two_d) ** 0.5)
    return np.array(vv)


def _timing(v: np.ndarray, dwell: np.ndarray, step: float) -> np.ndarray:
    """Time [s] at each speed sample: trapezoidal in 1 / v plus the dwell time of stops."""
    dt = 2 * step / np.maximum(v[1:] + v[:-1], 1e-9)
    return np.concatenate([[0.0], np.cumsum(dt + dwell[:-1])])


def _arc_length_at(t: np.ndarray, s: np.ndarray, v: np.ndarray, dwell: np.ndarray, t_knots: np.ndarray) -> np.ndarray:
    """Arc length at times ``t``: after the dwell at knot i, constant acceleration from v[i] to v[i+1]."""
    i = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, len(s) - 2)
    step = s[i + 1] - s[i]
    moving = 2 * step / np.maximum(v[i] + v[i + 1], 1e-9)
    accel = (v[i + 1] - v[i]) / moving
    tau = np.clip(t - t_knots[i] - dwell[i], 0.0, moving)
    return s[i] + np.minimum(v[i] * tau + 0.5 * accel * tau**2, step)


def make_trajectory(
    graph: PathGraph,
    ground: Ground,
    route: list[int],
    prof: MotionProfile,
    length: float | None,
    rng: np.random.Generator,
) -> Trajectory:
    """Drives ``route`` (node indices) with profile ``prof``, cut at ``length`` metres of lane (the whole
    route when None)."""
    lane = _offset_polyline(graph.nodes[np.asarray(route)], prof.lane_offset)
    pts, heading, kappa_geom, corner_s = _rounded_curve(lane, prof.corner_radius)
    s_geom = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    total = min(s_geom[-1], length) if length is not None else s_geom[-1]
    s = np.arange(0.0, total, prof.speed_step)
    s = np.append(s, total) if total - s[-1] > 1e-9 else s
    kappa = np.interp(s, s_geom, kappa_geom)
    # Curvature limits must hold before an arc starts: take the max curvature within +-1 m.
    kappa = maximum_filter1d(kappa, 2 * max(1, int(1.0 / prof.speed_step)) + 1, mode="nearest")
    stop_at = corner_s[rng.random(len(corner_s)) < prof.stop_prob] - prof.stop_backoff
    stop_at = stop_at[(stop_at > 0) & (stop_at < total)]
    stops = np.unique(np.searchsorted(s, stop_at))
    # The route starts and ends at rest: a stop on the sample next to either end would leave no distance to move
    # between two zero speeds (an endless time). A corner that close to a cut end is no stop.
    stops = stops[(stops > 1) & (stops < len(s) - 2)]
    dwell = np.zeros(len(s))
    dwell[stops] = rng.uniform(*prof.stop_time, len(stops))
    dwell[0] = REST

    target = total / prof.speed_avg
    lo, hi = prof.speed_avg, 6.0 * prof.speed_avg
    for _ in range(30):  # bisection: cruise speed whose average (stops included) hits speed_avg
        mid = 0.5 * (lo + hi)
        t_end = _timing(_speed_profile(kappa, stops, mid, prof), dwell, prof.speed_step)[-1]
        lo, hi = (mid, hi) if t_end > target else (lo, mid)
    v = _speed_profile(kappa, stops, hi, prof)
    t_knots = _timing(v, dwell, prof.speed_step)
    times = np.arange(0.0, t_knots[-1] + REST, 1.0 / RATE)
    s_t = _arc_length_at(times, s, v, dwell, t_knots)
    sigma = prof.smooth_sigma * RATE
    xy = np.stack([np.interp(s_t, s_geom, pts[:, 0]), np.interp(s_t, s_geom, pts[:, 1])], axis=1)
    xy = gaussian_filter1d(xy, sigma, axis=0, mode="nearest")
    yaw = gaussian_filter1d(np.interp(s_t, s_geom, heading), sigma, mode="nearest")
    return _on_ground(xy, yaw, ground, np.asarray(route))


def _on_ground(xy: np.ndarray, yaw: np.ndarray, ground: Ground, route: np.ndarray) -> Trajectory:
    """Poses on the terrain: z along the terrain normal, x along the heading projected onto the terrain."""
    x, y = xy[:, 0], xy[:, 1]
    gx, gy = ground.gradient(x, y)
    z_axis = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
    z_axis /= np.linalg.norm(z_axis, axis=1, keepdims=True)
    h = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
    x_axis = h - np.sum(h * z_axis, axis=1, keepdims=True) * z_axis
    x_axis /= np.linalg.norm(x_axis, axis=1, keepdims=True)
    y_axis = np.cross(z_axis, x_axis)
    quat = Rotation.from_matrix(np.stack([x_axis, y_axis, z_axis], axis=2)).as_quat()
    flips = np.concatenate([[1.0], np.sign(np.sum(quat[1:] * quat[:-1], axis=1))])
    quat *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    position = np.column_stack([x, y, ground.height(x, y)])
    return Trajectory(position, quat, route)


def localization_trajectory(world: World, scale: float, rng: np.random.Generator) -> Trajectory:
    """The route driven while localizing: ``PROFILES[world.name].length * scale`` metres."""
    prof = PROFILES[world.name]
    length = prof.length * scale
    # A world of one road (the tunnel) is driven end to end: a random walk would have to turn round in it.
    route = [0, 1] if len(world.graph.edges) == 1 else plan_route(world.graph, length, rng)
    return make_trajectory(world.graph, world.ground, route, prof, length, rng)


def mapping_trajectory(world: World, loc: Trajectory, rng: np.random.Generator) -> Trajectory:
    """The separate mapping run: the route nodes from the localization run's start to the first node past
    its end, driven in the opposite direction, so the lane (and the stops and timing) differ from the
    localization pass while covering it."""
    graph = world.graph
    route = list(loc.route)
    s_nodes = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(graph.nodes[route], axis=0), axis=1))])
    first_after = int(np.searchsorted(s_nodes, loc.length()))
    keep = route[: max(2, min(len(route), first_after + 1))]
    return make_trajectory(graph, world.ground, keep[::-1], PROFILES[world.name], None, rng)
