"""Trajectory errors: the paper's position RMSE between two runs, and APE against ground truth
(translation [m] and rotation [deg], no alignment: both trajectories are in the map frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

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


def _no_pairs(reference: Trajectory, estimate: Trajectory, max_diff: float) -> UserError:
    span = lambda tr: f"{tr.t[0]:.3f}..{tr.t[-1]:.3f} s" if len(tr) else "empty"  # noqa: E731
    return UserError(
        f"no poses are within {max_diff} s of each other (reference {span(reference)}, estimate "
        f"{span(estimate)}): check that both use the same clock"
    )


def paired_errors(reference: Trajectory, estimate: Trajectory, max_diff: float) -> PairedErrors:
    """Per-pair errors of ``estimate`` against ``reference``, paired by time as evo pairs them: each
    pose of the shorter trajectory with the nearest pose of the other, within ``max_diff`` seconds.
    Raises UserError when no pose pairs up."""
    if len(estimate) <= len(reference):
        ie, ir = associate(estimate.t, reference.t, max_diff)
        t = estimate.t[ie]
    else:
        ir, ie = associate(reference.t, estimate.t, max_diff)
        t = reference.t[ir]
    if ir.size == 0:
        raise _no_pairs(reference, estimate, max_diff)
    trans = np.linalg.norm(estimate.xyz[ie] - reference.xyz[ir], axis=1)
    rot = rotation_angle_deg(reference.quat[ir], estimate.quat[ie])
    return PairedErrors(t, trans, rot)


@dataclass(frozen=True)
class InterpolatedReference:
    index: np.ndarray  # (k,) the ``estimate`` poses paired
    xyz: np.ndarray  # (k, 3) the reference's position at their times
    quat: np.ndarray  # (k, 4) its orientation there, x y z w


def interpolated_reference(reference: Trajectory, estimate: Trajectory, max_diff: float) -> InterpolatedReference:
    """``reference`` interpolated at the time of each ``estimate`` pose (linear in position, slerp in
    rotation): for a dense ground truth (e.g. 100 Hz), so the pairing's time offset adds no error.
    Poses outside the reference's time span, or farther than ``max_diff`` seconds from the nearest
    reference pose, are skipped; none left is a UserError."""
    if len(reference) < 2:
        raise UserError("interpolating a reference trajectory needs at least two poses")
    ie, _ = associate(estimate.t, reference.t, max_diff)
    t = estimate.t[ie]
    inside = (t >= reference.t[0]) & (t <= reference.t[-1])
    ie, t = ie[inside], t[inside]
    if ie.size == 0:
        raise _no_pairs(reference, estimate, max_diff)
    xyz = np.stack([np.interp(t, reference.t, reference.xyz[:, k]) for k in range(3)], axis=1)
    quat = Slerp(reference.t, Rotation.from_quat(reference.quat))(t).as_quat()
    return InterpolatedReference(ie, xyz, quat)


def interpolated_errors(reference: Trajectory, estimate: Trajectory, max_diff: float) -> PairedErrors:
    """Errors of each ``estimate`` pose against ``reference`` interpolated at its time
    (``interpolated_reference``)."""
    at = interpolated_reference(reference, estimate, max_diff)
    trans = np.linalg.norm(estimate.xyz[at.index] - at.xyz, axis=1)
    return PairedErrors(estimate.t[at.index], trans, rotation_angle_deg(at.quat, estimate.quat[at.index]))


def position_rmse(a: Trajectory, b: Trajectory, max_diff: float) -> float:
    """RMSE [m] of the position difference between time-associated poses of two trajectories: the
    paper's accuracy figure (global map vs grid puzzle map)."""
    return paired_errors(a, b, max_diff).translation.rmse
