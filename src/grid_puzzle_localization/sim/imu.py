"""IMU measurements derived from a trajectory, with MEMS noise.

The IMU sits at base_link (frame ``base_link``) and samples at the trajectory rate (200 Hz). True
angular velocity is the body-frame rotation between neighbouring poses (central difference); true
specific force is R^T (a + g e_z) with a the central second difference of position and g = 9.80665 m/s^2.
Measurements add white noise and a bias that starts at a random turn-on value and random-walks,
following the continuous-time model used by Kalibr/EuRoC (noise densities below, ADIS16448-class MEMS):
discrete white sigma = density * sqrt(rate), bias step sigma = random_walk / sqrt(rate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.sim.trajectory import RATE, Trajectory

GRAVITY = 9.80665  # [m/s^2]


@dataclass(frozen=True)
class ImuNoise:
    gyro_noise_density: float = 1.7e-4  # [rad/s/sqrt(Hz)]
    gyro_random_walk: float = 2.0e-5  # [rad/s^2/sqrt(Hz)]
    accel_noise_density: float = 2.0e-3  # [m/s^2/sqrt(Hz)]
    accel_random_walk: float = 3.0e-3  # [m/s^3/sqrt(Hz)]
    gyro_turn_on_bias: float = 2.0e-3  # [rad/s] sigma of the initial bias
    accel_turn_on_bias: float = 2.0e-2  # [m/s^2] sigma of the initial bias


@dataclass(frozen=True)
class ImuData:
    """Samples at the trajectory times: ``gyro`` [rad/s] and ``accel`` [m/s^2] (n, 3) in base_link,
    measured (noisy) and ``true_*`` noise-free; ``gyro_bias`` / ``accel_bias`` the biases applied."""

    gyro: np.ndarray
    accel: np.ndarray
    true_gyro: np.ndarray
    true_accel: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray


def true_motion(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body angular velocity [rad/s], body specific force [m/s^2] and map-frame velocity [m/s], (n, 3) each,
    from central differences (one-sided at the ends)."""
    rot = Rotation.from_quat(trajectory.quat)
    n = len(trajectory.quat)
    lo, hi = np.maximum(np.arange(n) - 1, 0), np.minimum(np.arange(n) + 1, n - 1)
    span = (hi - lo) / RATE
    gyro = (rot[lo].inv() * rot[hi]).as_rotvec() / span[:, None]
    p = trajectory.position
    velocity = (p[hi] - p[lo]) / span[:, None]
    acc = np.zeros_like(p)
    acc[1:-1] = (p[2:] - 2 * p[1:-1] + p[:-2]) * RATE**2
    acc[0], acc[-1] = acc[1] if n > 2 else 0.0, acc[-2] if n > 2 else 0.0
    accel = rot.inv().apply(acc + np.array([0.0, 0.0, GRAVITY]))
    return gyro, accel, velocity


def simulate_imu(trajectory: Trajectory, rng: np.random.Generator, noise: ImuNoise | None = None) -> ImuData:
    noise = noise or ImuNoise()
    gyro, accel, _ = true_motion(trajectory)
    n = len(gyro)

    def bias(turn_on: float, walk: float) -> np.ndarray:
        start = rng.normal(0.0, turn_on, (1, 3))
        steps = rng.normal(0.0, walk / np.sqrt(RATE), (n, 3))
        steps[0] = 0.0
        return start + np.cumsum(steps, axis=0)

    gb = bias(noise.gyro_turn_on_bias, noise.gyro_random_walk)
    ab = bias(noise.accel_turn_on_bias, noise.accel_random_walk)
    g_meas = gyro + gb + rng.normal(0.0, noise.gyro_noise_density * np.sqrt(RATE), (n, 3))
    a_meas = accel + ab + rng.normal(0.0, noise.accel_noise_density * np.sqrt(RATE), (n, 3))
    return ImuData(g_meas, a_meas, gyro, accel, gb, ab)
