"""Time association of two trajectories: each pose of the first is paired with the nearest-in-time
pose of the second, if they are at most ``max_diff`` seconds apart (the rule evo uses)."""

from __future__ import annotations

import numpy as np

from grid_puzzle_localization.errors import UserError


def associate(
    t_a: np.ndarray, t_b: np.ndarray, max_diff: float, offset_b: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays (ia, ib) of the associated pairs. ``t_b + offset_b`` is compared with ``t_a``;
    both must be increasing. Several poses of ``a`` may share one pose of ``b`` when ``b`` is sparser."""
    if not max_diff >= 0:
        raise UserError(f"the association time difference must be >= 0 s (got {max_diff})")
    t_a = np.asarray(t_a, dtype=np.float64)
    t_b = np.asarray(t_b, dtype=np.float64) + offset_b
    if len(t_a) == 0 or len(t_b) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    right = np.clip(np.searchsorted(t_b, t_a), 1, len(t_b) - 1) if len(t_b) > 1 else np.zeros(len(t_a), np.int64)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(t_b[left] - t_a) <= np.abs(t_b[right] - t_a), left, right)
    keep = np.abs(t_b[nearest] - t_a) <= max_diff
    return np.flatnonzero(keep), nearest[keep]
