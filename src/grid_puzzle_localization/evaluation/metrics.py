"""Trajectory errors: the paper's position RMSE between two runs, and APE against ground truth
(translation [m] and rotation [deg], no alignment: both trajectories are in the map frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.association import associate
from grid_puzzle_localization.evaluation.trajectory import Trajectory


@dataclass(frozen=True)
class ErrorStats:
    rmse: float
    mean: float
    median: float
    max: float
    pairs: int

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64)
        return cls(float(np.sqrt(np.mean(e**2))), float(np.mean(e)), float(np.median(e)), float(np.max(e)), int(e.size))


@dataclass(frozen=True)
class PairedErrors:
    """Per-pair errors of ``estimate`` against ``reference``: times of the reference poses [s],
    translation error [m], rotation error [deg]."""

    t: np.ndarray
    translation_m: np.ndarray
    rotation_deg: np.ndarray

    @property
    def translation(self) -> ErrorStats:
        return ErrorStats.of(self.translation_m)

    @property
    def rotation(self) -> ErrorStats:
        return ErrorStats.of(self.rotation_deg)


def _quat_conj_mul(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """conj(q1) * q2 for (N, 4) quaternions (x, y, z, w): the rotation from q1 to q2."""
    x1, y1, z1, w1 = (-q1[:, 0], -q1[:, 1], -q1[:, 2], q1[:, 3])
    x2, y2, z2, w2 = q2.T
    return np.stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ],
        axis=1,
    )


def rotation_angle_deg(q_ref: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Angle of the relative rotation between paired orientations [deg], in [0, 180]."""
    d = _quat_conj_mul(q_ref, q_est)
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(d[:, :3], axis=1), np.abs(d[:, 3])))


def paired_errors(reference: Trajectory, estimate: Trajectory, max_diff: float) -> PairedErrors:
    """Associates ``estimate`` to ``reference`` in time (nearest within ``max_diff`` seconds) and
    returns the per-pair errors; raises UserError when no pose pairs up."""
    ia, ib = associate(reference.t, estimate.t, max_diff)
    if ia.size == 0:
        raise UserError(
            f"no poses are within {max_diff} s of each other (reference {reference.t[:1]}..{reference.t[-1:]} s, "
            f"estimate {estimate.t[:1]}..{estimate.t[-1:]} s): check that both use the same clock"
        )
    trans = np.linalg.norm(estimate.xyz[ib] - reference.xyz[ia], axis=1)
    rot = rotation_angle_deg(reference.quat[ia], estimate.quat[ib])
    return PairedErrors(reference.t[ia], trans, rot)


def position_rmse(a: Trajectory, b: Trajectory, max_diff: float) -> float:
    """RMSE [m] of the position difference between time-associated poses of two trajectories: the
    paper's accuracy figure (global map vs grid puzzle map)."""
    return paired_errors(a, b, max_diff).translation.rmse
