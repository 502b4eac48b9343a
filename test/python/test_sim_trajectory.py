"""Trajectories (full scale, no ray casting) and the IMU model derived from them."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.sim import trajectory, worlds
from grid_puzzle_localization.sim.imu import GRAVITY, ImuNoise, simulate_imu, true_motion
from grid_puzzle_localization.sim.movers import CAR
from grid_puzzle_localization.sim.scenario import _rng
from grid_puzzle_localization.sim.trajectory import (
    PROFILES,
    RATE,
    Trajectory,
    localization_trajectory,
    make_trajectory,
    mapping_trajectory,
    plan_route,
    transform,
)

SECTORS = [(-20, 20), (20, 70), (70, 110), (110, 160), (160, 200), (200, 250), (250, 290), (290, 340)]


@pytest.fixture(scope="module", params=["courtyard", "urban"])
def full(request):
    world = worlds.make_world(request.param, 0, 1.0)
    return world, localization_trajectory(world, 1.0, _rng(0, 1))


def test_length_speed_and_duration_match_the_profile(full):
    world, traj = full
    prof = PROFILES[world.name]
    assert traj.length() == pytest.approx(prof.length, rel=0.02)
    assert traj.length() / traj.duration == pytest.approx(prof.speed_avg, rel=0.03)
    expected = {"courtyard": 1270.0, "urban": 785.0}[world.name]
    assert traj.duration == pytest.approx(expected, rel=0.05)


def test_motion_is_smooth_and_physical(full):
    world, traj = full
    v = np.diff(traj.position[:, :2], axis=0) * RATE
    speed = np.linalg.norm(v, axis=1)
    accel = np.linalg.norm(np.diff(v, axis=0), axis=1) * RATE
    yaw_rate = np.diff(np.unwrap(traj.yaw())) * RATE
    limits = {"courtyard": (1.0, 1.5, 1.0), "urban": (15.0, 4.0, 1.0)}[world.name]
    assert speed.max() < limits[0]
    assert accel.max() < limits[1]  # [m/s^2], longitudinal and lateral together
    assert np.abs(yaw_rate).max() < limits[2]  # [rad/s]
    assert speed[0] < 0.05 and speed[-1] < 0.05  # starts and ends at rest
    # base_link sits on the terrain.
    np.testing.assert_allclose(traj.position[:, 2], world.ground.height(traj.position[:, 0], traj.position[:, 1]))


def test_all_eight_heading_sectors_occur_and_places_are_revisited(full):
    _, traj = full
    yaw = np.degrees(traj.yaw()) % 360.0
    for lo, hi in SECTORS:
        inside = ((yaw - lo) % 360.0) < (hi - lo)
        assert inside.sum() / RATE >= 1.0, f"less than 1 s with heading in [{lo}, {hi}) deg"
    route = list(traj.route)
    assert len(set(route)) < len(route)  # some crossing is passed more than once


def test_mapping_run_covers_the_route_in_the_other_direction(full):
    world, traj = full
    short = traj.truncated(60.0)
    mapping = mapping_trajectory(world, short, _rng(0, 2))
    # Every localization position has a mapping position within a lane change (a few metres).
    d = np.min(np.linalg.norm(short.position[::50, None, :2] - mapping.position[None, ::20, :2], axis=2), axis=1)
    assert d.max() < 8.0
    assert not np.allclose(mapping.position[0], short.position[0])


def test_duration_truncates_exactly():
    world = worlds.make_world("courtyard", 3, 0.25)
    traj = localization_trajectory(world, 0.25, _rng(3, 1)).truncated(12.5)
    assert traj.duration == pytest.approx(12.5)
    assert len(traj.position) == 12.5 * RATE + 1


def test_a_route_cut_just_past_a_stop_still_ends_in_time():
    """A stop before a corner that falls on the sample before the cut end (as a short `--duration` cuts a mover's
    route) must not stall the car there: the drive takes about length / average speed, not forever."""
    world = worlds.make_world("urban", 0, 1.0)
    rng = _rng(0, 7)
    route = plan_route(world.graph, 500.0, rng)
    always_stop = replace(CAR, stop_prob=1.0)
    lane = trajectory._offset_polyline(world.graph.nodes[np.asarray(route)], CAR.lane_offset)
    corner_s = trajectory._rounded_curve(lane, CAR.corner_radius)[3]
    stop_at = corner_s[corner_s > 100.0][0] - CAR.stop_backoff
    step = CAR.speed_step
    length = np.ceil(stop_at / step) * step + 0.5 * step  # the stop lands on the second-to-last speed sample
    traj = make_trajectory(world.graph, world.ground, route, always_stop, length, rng)
    assert traj.length() == pytest.approx(length, rel=0.02)
    assert traj.duration < 3.0 * length / CAR.speed_avg


def test_imu_matches_kinematics_and_noise_model():
    world = worlds.make_world("urban", 0, 0.25)
    traj = localization_trajectory(world, 0.25, _rng(0, 1)).truncated(120.0)
    gyro, accel, _ = true_motion(traj)
    # Integrating the true yaw rate (body z, nearly vertical) reproduces the heading change.
    yaw = np.unwrap(traj.yaw())
    up = Rotation.from_quat(traj.quat).apply(gyro)[:, 2]
    assert np.sum(up[1:-1]) / RATE == pytest.approx(yaw[-2] - yaw[1], abs=0.02)
    # At rest (start) the accelerometer measures gravity along the terrain normal.
    assert np.linalg.norm(accel[0]) == pytest.approx(GRAVITY, abs=0.05)
    # Noise: the measured-minus-true-minus-bias residual has the discrete white-noise sigma.
    noise = ImuNoise()
    imu = simulate_imu(traj, np.random.default_rng(1), noise)
    white = imu.gyro - imu.true_gyro - imu.gyro_bias
    assert np.std(white) == pytest.approx(noise.gyro_noise_density * np.sqrt(RATE), rel=0.05)
    white = imu.accel - imu.true_accel - imu.accel_bias
    assert np.std(white) == pytest.approx(noise.accel_noise_density * np.sqrt(RATE), rel=0.05)
    # Bias random walk: the variance of increments over 1 s is random_walk^2 * 1 s.
    step = np.diff(imu.accel_bias[:: int(RATE)], axis=0)
    assert np.std(step) == pytest.approx(noise.accel_random_walk, rel=0.2)


def test_stationary_imu_reads_gravity_only():
    quat = np.tile(Rotation.from_euler("z", 30, degrees=True).as_quat(), (401, 1))
    traj = Trajectory(np.zeros((401, 3)), quat, np.array([0, 1]))
    gyro, accel, velocity = true_motion(traj)
    np.testing.assert_allclose(gyro, 0.0, atol=1e-12)
    np.testing.assert_allclose(accel, np.tile([0.0, 0.0, GRAVITY], (401, 1)), atol=1e-9)
    np.testing.assert_allclose(velocity, 0.0, atol=1e-12)


@pytest.mark.parametrize("name", ["courtyard", "urban", "corridor"])
def test_worlds_and_routes_build_for_many_seeds_and_scales(name):
    for seed in range(4):
        for scale in (0.2, 0.25, 0.3, 0.37, 0.6, 1.0):
            world = worlds.make_world(name, seed, scale)
            x0, y0, x1, y1 = world.extent
            assert len(world.mesh.faces) > 500
            assert np.all((world.graph.nodes >= [x0, y0]) & (world.graph.nodes <= [x1, y1]))
            if scale <= 0.3:
                traj = localization_trajectory(world, scale, _rng(seed, 1))
                assert traj.length() == pytest.approx(PROFILES[name].length * scale, rel=0.02)


def test_corridor_is_a_straight_tunnel_driven_end_to_end_at_10_to_15_m_s():
    world = worlds.make_world("corridor", 0, 1.0)
    traj = localization_trajectory(world, 1.0, _rng(0, 1))
    assert traj.length() == pytest.approx(1000.0, rel=0.02)
    speed = np.linalg.norm(np.diff(traj.position[:, :2], axis=0), axis=1) * RATE
    cruising = speed[np.argmax(speed > 10.0) : len(speed) - np.argmax(speed[::-1] > 10.0)]
    assert cruising.min() >= 9.9 and speed.max() <= 15.0  # traffic: the speed varies, it does not stop
    assert cruising.max() - cruising.min() > 3.0
    assert len(cruising) / RATE > 0.9 * (traj.duration - 20.0)  # all but the start and the end
    np.testing.assert_allclose(traj.position[:, 1], traj.position[0, 1], atol=1e-9)  # one straight lane
    mapping = mapping_trajectory(world, traj, _rng(0, 2))
    assert np.sign(mapping.position[-1, 0] - mapping.position[0, 0]) == -np.sign(
        traj.position[-1, 0] - traj.position[0, 0]
    )


def test_frames_are_the_interpolated_poses_as_rotation_matrices():
    """frames() (component-major, float32 rotations) against interpolate() and scipy's quaternion maths."""
    world = worlds.make_world("courtyard", 1, 0.3)
    traj = localization_trajectory(world, 0.3, _rng(1, 1))
    t = np.random.default_rng(0).uniform(-1.0, traj.duration + 1.0, 3000)  # clamped outside the run
    pos, rot = traj.frames(t)
    p, q = traj.interpolate(t)
    np.testing.assert_allclose(pos.T, p, atol=1e-9)
    np.testing.assert_allclose(np.moveaxis(rot, 2, 0), Rotation.from_quat(q).as_matrix(), atol=2e-6)
    v = np.random.default_rng(1).normal(size=(3, len(t)))
    expected = Rotation.from_quat(q).apply(v.T) + p
    np.testing.assert_allclose(transform(rot, v, pos).T, expected, atol=1e-5)
    out = np.empty((len(t), 3), dtype=np.float32)
    assert transform(rot, np.array([0.2, 0.0, 1.3]), pos, out) is out
    np.testing.assert_allclose(out, Rotation.from_quat(q).apply([0.2, 0.0, 1.3]) + p, atol=1e-4)
