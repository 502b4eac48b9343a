"""Ray casting and beam patterns of the simulator against closed forms."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.sim import lidar, meshes, worlds
from grid_puzzle_localization.sim.lidar import Mount, SweepSimulator
from grid_puzzle_localization.sim.meshes import MeshBuilder
from grid_puzzle_localization.sim.movers import make_movers
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.sensors import SENSORS, SpinningLidar
from grid_puzzle_localization.sim.trajectory import RATE, Trajectory
from grid_puzzle_localization.util.iteration import pairwise, zip_equal


def _box_world(x0, y0, x1, y1, z0, z1):
    b = MeshBuilder()
    b.add(meshes.box(x0, y0, x1, y1, z0, z1), 0.5)
    return b.build()


def _straight(start, velocity, duration):
    """base_link moving at constant ``velocity`` (3,) [m/s] with identity orientation."""
    t = np.arange(int(duration * RATE) + 1) / RATE
    pos = np.asarray(start, float) + t[:, None] * np.asarray(velocity, float)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    return Trajectory(pos, quat, np.array([0, 1]))


def test_ray_ranges_inside_box_are_exact():
    mesh = _box_world(-3.0, -4.0, 5.0, 6.0, -1.0, 2.0)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = rng.uniform([-2.5, -3.5, -0.5], [4.5, 5.5, 1.5], size=(5000, 3))
    with RayCaster(mesh, threads=2) as caster:
        t, prim = caster.cast(o, d)
    # Closed form: distance to the first wall the ray leaves through (slab method from inside).
    lo, hi = np.array([-3.0, -4.0, -1.0]), np.array([5.0, 6.0, 2.0])
    with np.errstate(divide="ignore"):
        exits = np.where(d > 0, (hi - o) / d, np.where(d < 0, (lo - o) / d, np.inf))
    expected = exits.min(axis=1)
    assert np.all(prim >= 0)
    np.testing.assert_allclose(t, expected, rtol=1e-5, atol=1e-5)


def test_ray_missing_everything_reports_inf():
    mesh = _box_world(0.0, 0.0, 1.0, 1.0, 0.0, 1.0)
    with RayCaster(mesh) as caster:
        t, prim = caster.cast(np.array([[5.0, 5.0, 5.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert np.isinf(t[0]) and prim[0] == -1


def test_noise_free_sweep_hits_ground_plane_at_closed_form_range():
    """A stationary HDL-32E-like sensor h metres above a plane: ring r hits at h / sin(-elevation)."""
    h = 1.8
    sensor = replace(SENSORS["hdl32"], range_sigma=0.0, dropout=0.0, max_range=1000.0)
    mesh = _box_world(-2000.0, -2000.0, 2000.0, 2000.0, -10.0, 0.0)
    with RayCaster(mesh) as caster:
        sim = SweepSimulator(mesh, caster, sensor, Mount(np.array([0.0, 0.0, h]), np.eye(3)))
        pts = sim.simulate(_straight([0, 0, 0], [0, 0, 0], 1.0), 0.0, sensor.sweep(0), np.random.default_rng(0))
    el = sensor.elevations()
    down = np.flatnonzero(el < 0)
    assert set(np.unique(pts["ring"])) == set(down)  # upward rings see nothing
    r = np.sqrt(pts["x"].astype(float) ** 2 + pts["y"] ** 2 + pts["z"] ** 2)
    np.testing.assert_allclose(r, h / np.sin(-el[pts["ring"]]), rtol=2e-5)
    np.testing.assert_allclose(pts["z"], -h, atol=1e-4)
    assert np.sum(pts["ring"] == down[0]) == sensor.columns


def test_motion_distortion_uses_each_rays_own_pose():
    """A single horizontal ring moving at 10 m/s towards a wall: the forward ray fires half a sweep in,
    so its range is shorter by exactly v * t than at the sweep start."""
    wall_x, v = 40.0, 10.0
    sensor = SpinningLidar(
        "one_ring", 10.0, 0.1, 200.0, 0.0, 0.0, rings=1, elevation_min_deg=0.0, elevation_max_deg=0.0, columns=360
    )
    mesh = _box_world(wall_x, -100.0, wall_x + 1.0, 100.0, -50.0, 50.0)
    mount = Mount(np.array([0.3, 0.0, 1.0]), np.eye(3))
    with RayCaster(mesh) as caster:
        sim = SweepSimulator(mesh, caster, sensor, mount)
        pts = sim.simulate(_straight([0, 0, 0], [v, 0, 0], 2.0), 0.5, sensor.sweep(0), np.random.default_rng(0))
    forward = pts[np.abs(pts["y"]) < 1e-3]
    assert len(forward) == 1
    t_fire = 0.5 + float(forward["time"][0])
    assert forward["time"][0] == pytest.approx(0.05, abs=1e-9)  # azimuth 0 is half a turn after the start
    assert forward["x"][0] == pytest.approx(wall_x - 0.3 - v * t_fire, abs=1e-4)


def test_hdl32_pattern_statistics():
    s = SENSORS["hdl32"]
    sweep = s.sweep(3)
    assert s.rays_per_sweep == len(sweep.dt) == 69440
    el = np.degrees(np.arcsin(sweep.directions[:, 2]))
    for ring in range(32):
        np.testing.assert_allclose(el[sweep.ring == ring], -30.67 + ring * (41.34 / 31), atol=1e-9)
    assert np.all(np.bincount(sweep.ring) == 2170)
    assert sweep.dt.min() >= 0.0 and sweep.dt.max() < 0.1
    np.testing.assert_allclose(np.linalg.norm(sweep.directions, axis=1), 1.0)


def _coverage(directions: np.ndarray, cell_deg: float, el_lo: float, el_hi: float) -> float:
    az = np.degrees(np.arctan2(directions[:, 1], directions[:, 0])) + 180.0
    el = np.degrees(np.arcsin(directions[:, 2]))
    n_az, n_el = int(360 / cell_deg), int(np.ceil((el_hi - el_lo) / cell_deg))
    i = np.minimum((az / cell_deg).astype(int), n_az - 1)
    j = np.clip(((el - el_lo) / cell_deg).astype(int), 0, n_el - 1)
    return len(np.unique(i * n_el + j)) / (n_az * n_el)


def test_livox_coverage_grows_over_frames_and_hdl_repeats():
    s = SENSORS["livox"]
    assert s.rays_per_sweep * s.rate == 200000
    frames = [s.sweep(k).directions for k in range(10)]
    el = np.degrees(np.arcsin(np.concatenate(frames)[:, 2]))
    assert el.min() >= -7.0 - 1e-9 and el.max() <= 52.0 + 1e-9
    cov = [_coverage(np.concatenate(frames[:n]), 0.5, -7.0, 52.0) for n in (1, 2, 5, 10)]
    assert all(a < b for a, b in pairwise(cov))
    assert cov[0] < 0.3 and cov[-1] > 0.85
    # Frames differ: no direction of frame 0 reappears in frame 1.
    assert not np.any(np.all(np.isclose(frames[0][:100, None], frames[1][None, :100]), axis=2))
    h = SENSORS["hdl32"]
    one = _coverage(h.sweep(0).directions, 0.5, -31.0, 11.0)
    ten = _coverage(np.concatenate([h.sweep(k).directions for k in range(10)]), 0.5, -31.0, 11.0)
    assert one == ten


def test_mount_rotation_is_applied():
    """A lidar pitched down by 90 deg (looking at the floor with its x axis): the x-axis ray measures height."""
    sensor = SpinningLidar(
        "one_ring", 10.0, 0.1, 200.0, 0.0, 0.0, rings=1, elevation_min_deg=0.0, elevation_max_deg=0.0, columns=360
    )
    mesh = _box_world(-50.0, -50.0, 50.0, 50.0, -5.0, 0.0)
    rot = Rotation.from_euler("y", 90, degrees=True).as_matrix()
    with RayCaster(mesh) as caster:
        sim = SweepSimulator(mesh, caster, sensor, Mount(np.array([0.0, 0.0, 2.0]), rot))
        pts = sim.simulate(_straight([0, 0, 0], [0, 0, 0], 1.0), 0.0, sensor.sweep(0), np.random.default_rng(0))
    forward = pts[(np.abs(pts["y"]) < 1e-6) & (pts["x"] > 0)]
    assert forward["x"][0] == pytest.approx(2.0, abs=1e-4)


def test_movers_occlude_the_static_world():
    """A mover box between the sensor and a wall: rays through it return its range, the rest the wall's."""
    wall = _box_world(20.0, -50.0, 21.0, 50.0, -10.0, 10.0)
    b = MeshBuilder()
    b.add(meshes.box(5.0, -1.0, 6.0, 1.0, -10.0, 10.0), 0.9)
    mover = b.build()
    sensor = SpinningLidar(
        "one_ring", 10.0, 0.1, 200.0, 0.0, 0.0, rings=1, elevation_min_deg=0.0, elevation_max_deg=0.0, columns=3600
    )
    with RayCaster(wall) as caster:
        sim = SweepSimulator(wall, caster, sensor, Mount(np.zeros(3), np.eye(3)))
        traj = _straight([0, 0, 0], [0, 0, 0], 1.0)
        pts = sim.simulate(traj, 0.0, sensor.sweep(0), np.random.default_rng(0), mover)
        without = sim.simulate(traj, 0.0, sensor.sweep(0), np.random.default_rng(0))
    ahead = pts[np.abs(pts["y"] / pts["x"]) < 0.9 / 5.0]
    np.testing.assert_allclose(ahead["x"], 5.0, atol=1e-4)
    assert np.all(without["x"][np.abs(without["y"] / without["x"]) < 0.9 / 5.0] > 19.9)
    assert len(pts) == len(without)  # rays that hit the wall hit the mover instead: no return gained or lost


def test_mover_cull_keeps_every_ray_that_hits_a_mover():
    """The azimuth cull against brute force (every ray cast against the movers) for a moving, turning
    sensor among boxes at many bearings and distances, including one close enough to disable the cull."""
    rng = np.random.default_rng(5)
    sensor = SENSORS["hdl32"]
    sweep = sensor.sweep(0)
    t = np.arange(int(2.0 * RATE) + 1) / RATE
    yaw = 0.8 * t  # turning at 0.8 rad/s while driving at 8 m/s
    pos = np.column_stack([8.0 * t, np.zeros_like(t), np.zeros_like(t)])
    traj = Trajectory(pos, Rotation.from_euler("z", yaw).as_quat(), np.array([0, 1]))
    floor = _box_world(-200.0, -200.0, 200.0, 200.0, -10.0, -1.5)
    for near in (False, True):
        b = MeshBuilder()
        for _ in range(15):
            r, bearing = rng.uniform(4.0, 60.0), rng.uniform(-np.pi, np.pi)
            x, y = 4.0 + r * np.cos(bearing), r * np.sin(bearing)
            b.add(meshes.box(x - 2.2, y - 0.9, x + 2.2, y + 0.9, -1.5, 0.0, rng.uniform(0, np.pi)), 0.5)
        if near:
            b.add(meshes.box(4.2, 0.3, 4.6, 0.7, -1.5, 0.5), 0.5)  # a post within 0.7 m of the sensor path
        movers = b.build()
        with RayCaster(floor) as caster, RayCaster(movers, threads=1) as brute:
            sim = SweepSimulator(floor, caster, sensor, Mount(np.array([0.0, 0.0, 1.8]), np.eye(3)))
            origin, direction = sim.rays(traj, 0.5 + sweep.dt, sweep.directions)
            _, prim = brute.cast(origin, direction)
        hits = np.flatnonzero(prim >= 0)
        candidates = lidar._may_hit(origin, direction, movers)
        assert len(hits) > 1000 and np.all(np.isin(hits, candidates))
        if near:
            assert len(candidates) == len(origin)
        else:
            assert len(candidates) < 0.7 * len(origin)


def test_mover_mesh_is_the_mover_shape_at_its_interpolated_pose():
    """Movers.mesh_at against building the shapes directly at the pose interpolate() gives."""
    world = worlds.make_world("urban", 2, 0.3)
    movers = make_movers(world, 0.3, 30.0, 4, np.random.default_rng(2))
    mesh = movers.mesh_at(12.34, np.array([1e6, 1e6]))  # sensor far away: every mover present
    b = MeshBuilder()
    for traj, kind, refl in zip_equal(movers.trajectories, movers.kinds, movers.reflectivity):
        p, q = traj.interpolate(np.array([12.34]))
        x, y = p[0, :2]
        heading = Rotation.from_quat(q[0]).as_euler("ZYX")[0]
        if kind == "car":
            worlds.car(b, world.ground, x, y, heading, refl)
        else:
            z = float(world.ground.height(np.array(x), np.array(y)))
            b.add(meshes.box(x - 0.15, y - 0.25, x + 0.15, y + 0.25, z, z + 1.75, heading), refl)
    expected = b.build()
    np.testing.assert_allclose(mesh.triangles, expected.triangles, atol=2e-3)
    np.testing.assert_array_equal(mesh.reflectivity, expected.reflectivity)
    near = movers.trajectories[0].interpolate(np.array([12.34]))[0][0, :2]
    assert len(movers.mesh_at(12.34, near).faces) < len(mesh.faces)  # the one at the sensor is left out
