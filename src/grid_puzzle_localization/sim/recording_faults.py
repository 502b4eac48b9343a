"""Motions and recordings that real data holds and a smooth simulated drive does not.

- A hand-held sensor swings about its vertical axis while the person walks: ``YawSwing`` adds
  ``delta(t) = swing / 2 * cos(pi * t / half_period)`` [rad] to the yaw of every pose (a rotation about
  base_link's own z axis; positions unchanged). The yaw goes from one extreme to the other in
  ``half_period`` seconds, so scans taken ``half_period`` apart (2 Hz for the default 0.5 s) see the
  whole swing between consecutive scans, reversing each time.
- Recordings with gaps (dropped packets, a paused recorder): ``in_gaps`` marks the times inside any
  ``(start, length)`` interval, whose messages the bag leaves out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.sim.trajectory import Trajectory


@dataclass(frozen=True)
class YawSwing:
    swing_deg: float = 60.0  # [deg] from one extreme to the other (+-30 deg about the heading)
    half_period_s: float = 0.5  # [s] to go from one extreme to the other

    def offset(self, t: np.ndarray) -> np.ndarray:
        """Yaw added at times ``t`` [s] [rad]."""
        return 0.5 * math.radians(self.swing_deg) * np.cos(np.pi * np.asarray(t, dtype=np.float64) / self.half_period_s)

    def check(self) -> None:
        if not (0.0 < self.swing_deg <= 180.0 and self.half_period_s > 0.0):
            raise UserError(
                f"yaw swing {self.swing_deg} deg in {self.half_period_s} s: the swing must be in (0, 180] deg and"
                " its half period > 0 s"
            )


def with_yaw_swing(traj: Trajectory, swing: YawSwing) -> Trajectory:
    """``traj`` with each pose turned by ``swing.offset(t)`` about its own z axis."""
    turned = Rotation.from_quat(traj.quat) * Rotation.from_euler("z", swing.offset(traj.times))
    quat = turned.as_quat()
    flips = np.concatenate([[1.0], np.sign(np.sum(quat[1:] * quat[:-1], axis=1))])  # sign-continuous
    quat *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    return Trajectory(traj.position, quat, traj.route)


def check_gaps(gaps: tuple[tuple[float, float], ...], duration: float) -> None:
    for start, length in gaps:
        if not (math.isfinite(start) and math.isfinite(length) and length > 0 and 0 < start < duration):
            raise UserError(
                f"--gap {start} {length}: the gap must start inside the run (0 < start < {duration:.1f} s) and last"
                " more than 0 s"
            )


def in_gaps(t: np.ndarray, gaps: tuple[tuple[float, float], ...]) -> np.ndarray:
    """Mask of the times ``t`` [s from the run start] inside any gap ``[start, start + length)``."""
    t = np.asarray(t, dtype=np.float64)
    mask = np.zeros(t.shape, dtype=bool)
    for start, length in gaps:
        mask |= (t >= start) & (t < start + length)
    return mask
