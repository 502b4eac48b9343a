"""Pose and time files of a recording: one pose per scan, as KITTI lines, TUM lines or 4x4 blocks.

- ``kitti``: 12 numbers a line, the top 3 rows of the 4x4 pose, row-major (KITTI odometry, SLAM outputs).
- ``tum``: ``t tx ty tz qx qy qz qw`` a line; the times come with the poses.
- ``matrix``: 4 lines of 4 numbers per pose (blank lines between poses allowed).

A pose maps points of the robot (base) frame into the map frame. It must be a rigid transform: a rotation
(orthonormal, determinant +1, to ``RIGID_TOLERANCE``) and, for 4x4 blocks, a last row 0 0 0 1.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grid_puzzle_localization.errors import UserError

POSE_FORMATS = ("kitti", "tum", "matrix")
# Numbers a line of each format and what they are (for the error on a line of another width).
LINE_LAYOUTS = {
    "kitti": (12, "the top 3 rows of the 4x4 pose, row-major"),
    "tum": (8, "t tx ty tz qx qy qz qw"),
    "matrix": (4, "one row of a 4x4 pose"),
}
RIGID_TOLERANCE = 1e-3  # max |R^T R - I| entry: text files round poses to about 6 digits


def read_rows(path: str | os.PathLike, what: str, fmt: str | None = None) -> list[tuple[int, list[float]]]:
    """(line number, numbers) of the non-empty, non-comment (``#``) lines of a text file of numbers separated
    by spaces or commas. With ``fmt`` (one of ``LINE_LAYOUTS``) every line must have that format's width.
    ``what`` names the file in the error when it cannot be read ("trajectory", "pose file"...)."""
    width, layout = LINE_LAYOUTS[fmt] if fmt else (None, "")
    rows = []
    try:
        with open(path) as f:
            for line_no, line in enumerate(f, 1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                try:
                    values = [float(v) for v in text.replace(",", " ").split()]
                except ValueError as err:
                    raise UserError(f"{path}:{line_no}: not a number ({err})") from None
                if width is not None and len(values) != width:
                    raise UserError(
                        f"{path}:{line_no}: a {fmt} line has {width} numbers ({layout}), found {len(values)}"
                    )
                rows.append((line_no, values))
    except OSError as err:
        raise UserError(f"cannot read {what} {path}: {err.strerror}; check the path") from None
    return rows


def guess_format(path: str | os.PathLike) -> str:
    """The format of a pose file from the numbers on its first line (12: kitti, 8: tum, 4: matrix)."""
    rows = read_rows(path, "pose file")
    if not rows:
        raise UserError(f"{path}: no poses in the file")
    formats = {width: fmt for fmt, (width, _) in LINE_LAYOUTS.items()}
    width = len(rows[0][1])
    if width not in formats:
        raise UserError(
            f"{path}:{rows[0][0]}: {width} numbers on a line; a pose file has 12 (KITTI 3x4), 8 (TUM) or 4 (4x4"
            " blocks) a line; name it with --pose-format"
        )
    return formats[width]


def read_poses(path: str | os.PathLike, fmt: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Poses ``(N, 4, 4)`` and, for TUM, their times ``(N,)`` [s] (else None). Raises UserError naming
    the file and the line of a bad pose."""
    if fmt not in POSE_FORMATS:
        raise UserError(f"unknown pose format '{fmt}'; use one of {', '.join(POSE_FORMATS)}")
    rows = read_rows(path, "pose file", fmt)
    if not rows:
        raise UserError(f"{path}: no poses in the file")
    data = np.array([values for _, values in rows], dtype=np.float64)
    lines = [line_no for line_no, _ in rows]
    times = None
    if fmt == "kitti":
        poses = np.tile(np.eye(4), (len(data), 1, 1))
        poses[:, :3, :] = data.reshape(-1, 3, 4)
    elif fmt == "tum":
        from scipy.spatial.transform import Rotation

        times = data[:, 0]
        norms = np.linalg.norm(data[:, 4:8], axis=1)
        bad = np.flatnonzero(~(np.abs(norms - 1.0) <= RIGID_TOLERANCE))
        if len(bad):
            raise UserError(
                f"{path}:{lines[bad[0]]}: quaternion of norm {norms[bad[0]]:.6g}, not a rotation; give unit quaternions"
            )
        poses = np.tile(np.eye(4), (len(data), 1, 1))
        poses[:, :3, :3] = Rotation.from_quat(data[:, 4:8]).as_matrix()
        poses[:, :3, 3] = data[:, 1:4]
    else:
        if len(data) % 4:
            raise UserError(f"{path}: {len(data)} rows of 4 numbers do not make whole 4x4 poses (4 rows each)")
        poses = data.reshape(-1, 4, 4)
        lines = lines[::4]
    check_rigid(poses, path, lines)
    return poses, times


def check_rigid(poses: np.ndarray, path: str | os.PathLike, lines: list[int]) -> None:
    """Raises UserError at the first pose that is not a rigid transform (or holds NaN/inf)."""
    rot = poses[:, :3, :3]
    finite = np.isfinite(poses).all(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        ortho = np.abs(np.einsum("nji,njk->nik", rot, rot) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(np.where(finite[:, None, None], rot, 0.0))
        last_row = np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1)
    bad = np.flatnonzero(~finite | ~(ortho <= RIGID_TOLERANCE) | ~(det > 0) | ~(last_row <= RIGID_TOLERANCE))
    if len(bad):
        k = bad[0]
        why = (
            "holds NaN or infinite values"
            if not finite[k]
            else f"last row {poses[k, 3].tolist()} is not 0 0 0 1"
            if last_row[k] > RIGID_TOLERANCE
            else f"rotation part is not a rotation (|R^T R - I| = {ortho[k]:.3g}, det {det[k]:.3g})"
        )
        raise UserError(f"{path}:{lines[k]}: pose {k} is not a rigid transform: {why}; fix the pose file")


def read_times(path: str | os.PathLike) -> np.ndarray:
    """Scan times [s], one number a line (the first number of a line when there are more)."""
    rows = read_rows(path, "times file")
    if not rows:
        raise UserError(f"{path}: no times in the file")
    return np.array([values[0] for _, values in rows], dtype=np.float64)


def check_times(times: np.ndarray, source: str | Path) -> None:
    """Raises UserError unless the times are finite and strictly increasing."""
    if not np.isfinite(times).all():
        raise UserError(f"{source}: a time is NaN or infinite")
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.argmax(steps <= 0)) + 1
        raise UserError(f"{source}: times must increase strictly (scan {k} at {times[k]!r} s does not); fix the times")
