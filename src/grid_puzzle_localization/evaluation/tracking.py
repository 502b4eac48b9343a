"""Whether a localizer kept track over a recording: per played scan, did it publish a pose and how far
from the reference, how long it went without a good pose, and how soon it had one after each gap.

A scan is *tracked* when a pose is published within ``max_diff`` seconds of its stamp and lies within
``lost_m`` and ``lost_deg`` of the reference pose at that time; otherwise (no pose, or a pose farther off in
position or heading) it is *lost*.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.evaluation.association import associate
from grid_puzzle_localization.evaluation.metrics import rotation_angle_deg
from grid_puzzle_localization.evaluation.trajectory import Trajectory

LOST_M = 1.0  # [m] a pose farther than this from the reference counts as lost
LOST_DEG = 5.0  # [deg] as does a pose turned by more than this
GAP_FACTOR = 3.0  # a pause longer than this many median scan intervals is a gap


@dataclass(frozen=True)
class Tracking:
    scans: int  # played scans that have a reference pose
    published: int  # of them with a published pose
    tracked: int  # of them with a published pose within LOST_M and LOST_DEG
    published_far: int  # of them with a published pose farther than LOST_M (whatever its heading)
    translation_rmse_m: float | None  # over the published poses
    translation_max_m: float | None
    rotation_max_deg: float | None
    longest_loss_s: float  # longest span from a lost scan to the next tracked one (0 if none lost)
    recovery_after_gaps_s: list[float | None]  # per gap: first tracked scan after it minus its end; None: never


def tracking(
    reference: Trajectory,
    estimate: Trajectory,
    scan_stamps: np.ndarray,
    max_diff: float,
    lost_m: float = LOST_M,
    lost_deg: float = LOST_DEG,
) -> Tracking:
    """Tracking figures of ``estimate`` over the scans stamped ``scan_stamps`` [s] (increasing), the
    reference being ``reference`` at those stamps."""
    stamps = np.asarray(scan_stamps, dtype=np.float64)
    i_scan, i_ref = associate(stamps, reference.t, max_diff)
    stamps, truth, truth_quat = stamps[i_scan], reference.xyz[i_ref], reference.quat[i_ref]
    error, turn = np.full(len(stamps), np.inf), np.full(len(stamps), np.inf)
    i_s, i_e = associate(stamps, estimate.t, max_diff)
    error[i_s] = np.linalg.norm(estimate.xyz[i_e] - truth[i_s], axis=1)
    turn[i_s] = rotation_angle_deg(truth_quat[i_s], estimate.quat[i_e])
    good = (error <= lost_m) & (turn <= lost_deg)
    published = np.isfinite(error)
    longest, lost_since = 0.0, None
    for t, ok in zip(stamps.tolist(), good.tolist()):
        if not ok and lost_since is None:
            lost_since = t
        elif ok and lost_since is not None:
            longest, lost_since = max(longest, t - lost_since), None
    if lost_since is not None:
        longest = max(longest, stamps[-1] - lost_since)
    recoveries: list[float | None] = []
    if len(stamps) > 2:
        steps = np.diff(stamps)
        for k in np.flatnonzero(steps > GAP_FACTOR * np.median(steps)):
            after = np.flatnonzero(good[k + 1 :])
            recoveries.append(float(stamps[k + 1 + after[0]] - stamps[k + 1]) if len(after) else None)
    return Tracking(
        scans=len(stamps),
        published=int(published.sum()),
        tracked=int(good.sum()),
        published_far=int((published & (error > lost_m)).sum()),
        translation_rmse_m=float(np.sqrt(np.mean(error[published] ** 2))) if published.any() else None,
        translation_max_m=float(error[published].max()) if published.any() else None,
        rotation_max_deg=float(turn[published].max()) if published.any() else None,
        longest_loss_s=float(longest),
        recovery_after_gaps_s=recoveries,
    )
