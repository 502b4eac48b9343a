"""Poses: TUM trajectory files, interpolation to scan stamps, and the sensor extrinsic.

A TUM line is ``stamp tx ty tz qx qy qz qw`` (seconds, metres, unit quaternion); ``#`` starts a
comment. A pose is a 4x4 float64 homogeneous matrix ``T_map_robot`` mapping robot-frame points into
the map frame.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from grid_puzzle_localization.errors import UserError


def pose_matrix(translation: np.ndarray, quaternion_xyzw: np.ndarray) -> np.ndarray:
    """4x4 pose from a translation [m] and a quaternion (x, y, z, w); the quaternion is normalised."""
    q = np.asarray(quaternion_xyzw, dtype=np.float64)
    if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.0):
        raise UserError(f"quaternion {q.tolist()} is not a rotation: give four finite numbers, not all zero")
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_quat(q).as_matrix()
    pose[:3, 3] = translation
    return pose


def parse_extrinsic(values: list[float] | None) -> np.ndarray:
    """Sensor->robot extrinsic ``T_robot_sensor`` from ``[x, y, z, qx, qy, qz, qw]`` (None: identity)."""
    if values is None:
        return np.eye(4)
    if len(values) != 7 or not all(math.isfinite(v) for v in values):
        raise UserError(f"extrinsic must be 7 finite numbers 'x y z qx qy qz qw' (got {values})")
    return pose_matrix(np.array(values[:3]), np.array(values[3:]))


@dataclass(frozen=True)
class Trajectory:
    stamps: np.ndarray  # (N,) seconds, strictly increasing
    translations: np.ndarray  # (N, 3) metres
    rotations: Rotation  # N rotations

    def __len__(self) -> int:
        return len(self.stamps)

    def pose(self, index: int) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3] = self.rotations[index].as_matrix()
        pose[:3, 3] = self.translations[index]
        return pose

    @functools.cached_property
    def _slerp(self) -> Slerp:
        return Slerp(self.stamps, self.rotations)

    def interpolate(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(M, 4, 4)`` at ``stamps`` (linear in translation, slerp in rotation) and a mask of
        the stamps that lie inside the trajectory's time span (poses outside it are not extrapolated)."""
        stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
        inside = (stamps >= self.stamps[0]) & (stamps <= self.stamps[-1])
        poses = np.tile(np.eye(4), (len(stamps), 1, 1))
        if inside.any() and len(self.stamps) == 1:
            poses[inside] = self.pose(0)
        elif inside.any():
            t = stamps[inside]
            for k in range(3):
                poses[inside, k, 3] = np.interp(t, self.stamps, self.translations[:, k])
            poses[inside, :3, :3] = self._slerp(t).as_matrix()
        return poses, inside


def read_tum(path: str | os.PathLike) -> Trajectory:
    """Reads a TUM trajectory; raises UserError naming the file and line on bad content."""
    rows = []
    try:
        with open(path, encoding="utf-8") as f:
            for number, line in enumerate(f, 1):
                text = line.split("#", 1)[0].strip()
                if not text:
                    continue
                fields = text.split()
                try:
                    row = [float(v) for v in fields]
                except ValueError:
                    row = []
                if len(row) != 8 or not all(math.isfinite(v) for v in row):
                    raise UserError(
                        f"{path}:{number}: expected 8 numbers 'stamp tx ty tz qx qy qz qw' (TUM format), got '{text}'"
                    )
                rows.append(row)
    except OSError as err:
        raise UserError(f"cannot read trajectory {path}: {err.strerror}; give an existing TUM file") from err
    if not rows:
        raise UserError(f"trajectory {path} holds no poses; give a TUM file with at least one line")
    data = np.array(rows, dtype=np.float64)
    if np.any(np.diff(data[:, 0]) <= 0.0):
        raise UserError(f"trajectory {path}: stamps must be strictly increasing; sort it and remove duplicates")
    norms = np.linalg.norm(data[:, 4:8], axis=1)
    if np.any(norms == 0.0):
        raise UserError(f"trajectory {path}: a quaternion is all zeros (line {int(np.argmin(norms)) + 1} of the poses)")
    return Trajectory(data[:, 0], data[:, 1:4], Rotation.from_quat(data[:, 4:8]))


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``pose`` (4x4) applied to ``points`` ``(N, 3)``, as float64."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return points @ pose[:3, :3].T + pose[:3, 3]
