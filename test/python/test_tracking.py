"""Tracking figures (published, tracked, longest loss, recovery after gaps) on hand-built trajectories."""

import numpy as np
import pytest

from grid_puzzle_localization.evaluation.tracking import tracking
from grid_puzzle_localization.evaluation.trajectory import make_trajectory


def trajectory(t, x, yaw_deg=0.0):
    t = np.asarray(t, dtype=float)
    xyz = np.column_stack([x, np.zeros_like(t), np.zeros_like(t)])
    half = np.radians(np.broadcast_to(yaw_deg, t.shape)) / 2
    return make_trajectory(t, xyz, np.column_stack([0 * t, 0 * t, np.sin(half), np.cos(half)]))


def test_losses_and_recoveries_against_hand_counts():
    # Scans every 0.5 s from 0 to 9.5 s, then a 5 s gap, then every 0.5 s from 15 to 19.5 s.
    stamps = np.concatenate([np.arange(0, 10, 0.5), np.arange(15, 20, 0.5)])
    reference = trajectory(stamps, 10.0 * stamps)
    error = np.zeros(len(stamps))
    error[4:8] = 3.0  # lost from 2.0 s, tracked again at 4.0 s
    error[20:22] = 2.0  # lost after the gap for 15.0 and 15.5 s, tracked at 16.0 s
    error[30:] = 0.2
    published = np.ones(len(stamps), dtype=bool)
    published[[10, 11, 12]] = False  # nothing published at 5.0-6.0 s: lost, tracked again at 6.5 s
    estimate = trajectory(stamps[published], 10.0 * stamps[published] + error[published])
    got = tracking(reference, estimate, stamps, max_diff=0.05, lost_m=1.0)
    assert got.scans == 30 and got.published == 27
    assert got.tracked == 30 - 4 - 3 - 2
    assert got.published_far == 4 + 2  # 3 m and 2 m off; 0.2 m is within 1 m
    assert got.longest_loss_s == pytest.approx(2.0)  # 2.0 s -> 4.0 s
    assert got.recovery_after_gaps_s == [pytest.approx(1.0)]  # first scan after the gap 15.0 s, tracked 16.0 s
    errors = error[published]
    assert got.translation_rmse_m == pytest.approx(np.sqrt(np.mean(errors**2)))
    assert got.translation_max_m == pytest.approx(3.0)
    assert got.rotation_max_deg == pytest.approx(0.0)


def test_a_pose_turned_too_far_is_lost_even_in_the_right_place():
    stamps = np.arange(0, 5, 0.5)
    reference = trajectory(stamps, stamps)
    yaw = np.where(np.arange(10) % 2 == 1, 60.0, 0.0)  # every other pose 60 deg off, positions exact
    got = tracking(reference, trajectory(stamps, stamps, yaw), stamps, max_diff=0.05)
    assert got.published == 10 and got.tracked == 5 and got.translation_max_m == 0.0
    assert got.published_far == 0
    assert got.rotation_max_deg == pytest.approx(60.0)
    assert got.longest_loss_s == pytest.approx(0.5)


def test_never_recovering_after_a_gap_and_lost_until_the_end():
    stamps = np.concatenate([np.arange(0, 5, 0.5), np.arange(10, 12, 0.5)])
    reference = trajectory(stamps, stamps)
    estimate = trajectory(stamps[:10], stamps[:10])  # silent after the gap
    got = tracking(reference, estimate, stamps, max_diff=0.05)
    assert got.published == got.tracked == 10
    assert got.recovery_after_gaps_s == [None]
    assert got.longest_loss_s == pytest.approx(1.5)  # 10.0 s to the last scan at 11.5 s
