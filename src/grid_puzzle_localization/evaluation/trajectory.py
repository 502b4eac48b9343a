"""Trajectories as arrays and the TUM file format.

TUM: one pose per line, ``timestamp tx ty tz qx qy qz qw`` (seconds; metres; unit quaternion, scalar
last), separated by spaces (commas are read too); lines starting with ``#`` are comments."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.recordings.poses import read_rows
from grid_puzzle_localization.util.atomic import atomic_write
from grid_puzzle_localization.util.iteration import zip_equal


@dataclass(frozen=True)
class Trajectory:
    """Poses at strictly increasing times: ``t`` (N,) [s], ``xyz`` (N, 3) [m], ``quat`` (N, 4) unit
    quaternions (x, y, z, w)."""

    t: np.ndarray
    xyz: np.ndarray
    quat: np.ndarray

    def __post_init__(self):
        n = len(self.t)
        if self.t.shape != (n,) or self.xyz.shape != (n, 3) or self.quat.shape != (n, 4):
            shapes = f"t {self.t.shape}, xyz {self.xyz.shape}, quat {self.quat.shape}"
            raise ValueError(f"trajectory arrays disagree: {shapes}")

    def __len__(self) -> int:
        return len(self.t)


def _checked(t: np.ndarray, xyz: np.ndarray, quat: np.ndarray, source: str) -> Trajectory:
    if len(t) and not np.all(np.isfinite(np.hstack([t[:, None], xyz, quat]))):
        raise UserError(f"{source}: a pose has a NaN or infinite value; fix or drop that line")
    if np.any(np.diff(t) <= 0):
        first = int(np.argmax(np.diff(t) <= 0)) + 1
        raise UserError(f"{source}: timestamps must increase strictly (pose {first} at t={t[first]} does not)")
    norms = np.linalg.norm(quat, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        bad = int(np.argmax(np.abs(norms - 1.0) > 1e-3))
        raise UserError(f"{source}: pose {bad} has a quaternion of norm {norms[bad]:.6f}, not a unit quaternion")
    return Trajectory(t, xyz, quat / norms[:, None] if len(t) else quat)


def make_trajectory(t, xyz, quat, source: str = "trajectory") -> Trajectory:
    """Validated trajectory from array-likes (increasing times, finite values, unit quaternions)."""
    return _checked(
        np.asarray(t, dtype=np.float64).reshape(-1),
        np.asarray(xyz, dtype=np.float64).reshape(-1, 3),
        np.asarray(quat, dtype=np.float64).reshape(-1, 4),
        source,
    )


def read_tum(path: str | os.PathLike) -> Trajectory:
    """Reads a TUM trajectory file; raises UserError naming the file and line on bad input."""
    rows = read_rows(path, "trajectory", "tum")
    data = np.array([values for _, values in rows], dtype=np.float64).reshape(-1, 8)
    return _checked(data[:, 0], data[:, 1:4], data[:, 4:8], str(path))


def write_tum(path: str | os.PathLike, traj: Trajectory, stamps_ns: np.ndarray | None = None) -> None:
    """Writes ``traj`` as TUM (9 decimals: nanosecond times, nanometre positions), atomically.

    float64 seconds resolve only about 0.2 us at epoch times (1.7e9 s); pass the same times as integer
    nanoseconds in ``stamps_ns`` to have them written digit for digit."""
    with atomic_write(path) as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        if stamps_ns is None:
            np.savetxt(f, np.hstack([traj.t[:, None], traj.xyz, traj.quat]), fmt="%.9f")
            return
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        if stamps_ns.shape != traj.t.shape or np.any(np.abs(stamps_ns * 1e-9 - traj.t) > 1e-6):
            raise ValueError("stamps_ns must hold the trajectory's times in nanoseconds")
        poses = io.StringIO()
        np.savetxt(poses, np.hstack([traj.xyz, traj.quat]), fmt="%.9f")
        secs, nsecs = np.divmod(stamps_ns, 10**9)
        lines = poses.getvalue().splitlines()
        f.writelines(f"{s}.{n:09d} {pose}\n" for s, n, pose in zip_equal(secs.tolist(), nsecs.tolist(), lines))
