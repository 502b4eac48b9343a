"""How a run started: when the localizer published its first pose, and its first pose from an accepted match,
after the first played scan (bag time), and how far each was from the reference then (position [m], yaw [deg])."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.association import associate
from grid_puzzle_localization.evaluation.metrics import interpolated_reference
from grid_puzzle_localization.evaluation.trajectory import Trajectory

SAME_STAMP_S = 1e-4  # a status and a pose of one scan carry its header stamp (written to the nanosecond)


def yaw_of(quat: np.ndarray) -> np.ndarray:
    """Yaw [rad] of (n, 4) quaternions x y z w: fixed-axis roll, pitch, yaw (REP 103), as sim/trajectory.py reads it."""
    return Rotation.from_quat(np.asarray(quat, dtype=np.float64).reshape(-1, 4)).as_euler("ZYX")[:, 0]


def yaw_difference_deg(q_ref: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """|yaw(est) - yaw(ref)| [deg], wrapped to [0, 180]."""
    d = yaw_of(q_est) - yaw_of(q_ref)
    return np.degrees(np.abs(np.arctan2(np.sin(d), np.cos(d))))


@dataclass(frozen=True)
class FirstPose:
    stamp_s: float  # the pose's stamp (bag time)
    after_s: float  # its stamp minus the first played scan's [s]
    translation_error_m: float | None  # against the reference at its stamp; None without one there
    yaw_error_deg: float | None


def first_pose(
    estimate: Trajectory,
    first_scan_stamp_s: float,
    reference: Trajectory | None = None,
    accepted_stamps: np.ndarray | None = None,
    max_diff_s: float = 0.05,
) -> FirstPose | None:
    """The first pose of ``estimate`` (with ``accepted_stamps``: the first whose stamp is one of them, i.e. from a
    scan whose match the localizer accepted) and its error against ``reference`` interpolated at its stamp (the
    reference must have a pose within ``max_diff_s``). None when there is no such pose."""
    index = np.arange(len(estimate))
    if accepted_stamps is not None:
        index, _ = associate(estimate.t, np.sort(np.asarray(accepted_stamps, dtype=np.float64)), SAME_STAMP_S)
    if index.size == 0:
        return None
    i = int(index[0])
    one = Trajectory(estimate.t[i : i + 1], estimate.xyz[i : i + 1], estimate.quat[i : i + 1])
    translation = yaw = None
    if reference is not None and len(reference) >= 2:
        try:
            at = interpolated_reference(reference, one, max_diff_s)
        except UserError:  # the reference does not cover that moment
            at = None
        if at is not None:
            translation = float(np.linalg.norm(one.xyz[0] - at.xyz[0]))
            yaw = float(yaw_difference_deg(at.quat, one.quat)[0])
    return FirstPose(float(one.t[0]), float(one.t[0] - first_scan_stamp_s), translation, yaw)


def start_figures(
    estimate: Trajectory,
    first_scan_stamp_s: float | None,
    reference: Trajectory | None,
    accepted_stamps: np.ndarray | None,
    max_diff_s: float,
) -> dict | None:
    """summary.json's ``start`` of a mode: ``first_pose`` (the first published) and ``first_accepted_pose`` (absent
    when the scan times do not say which matches were accepted), each None when there was none; None without the
    first scan's stamp."""
    if first_scan_stamp_s is None:
        return None

    def figures(accepted: np.ndarray | None) -> dict | None:
        found = first_pose(estimate, first_scan_stamp_s, reference, accepted, max_diff_s)
        return None if found is None else dataclasses.asdict(found)

    result = {"first_scan_stamp_s": first_scan_stamp_s, "first_pose": figures(None)}
    if accepted_stamps is not None:
        result["first_accepted_pose"] = figures(accepted_stamps)
    return result
