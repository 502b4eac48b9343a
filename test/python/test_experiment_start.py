"""`gpm experiment --start`: the offset start pose and the hint against closed forms and sample statistics, what
the launch and the recorder are given per start, the checks of the options, and the time to the first pose and
its error on hand-built trajectories."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from grid_puzzle_localization.commands import experiment as experiment_command
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.first_pose import first_pose, start_figures, yaw_difference_deg
from grid_puzzle_localization.evaluation.trajectory import make_trajectory
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.runner import launch_args, recorder_args
from grid_puzzle_localization.experiment.start import StartSetting, offset_pose, sample_hint, start_from
from grid_puzzle_localization.report.markdown import start_table

POSE = [10.0, -5.0, 1.5, 0.02, -0.01, 3.0]


def yaw_quat(yaw: np.ndarray) -> np.ndarray:
    yaw = np.asarray(yaw, dtype=float)
    return np.stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)


@pytest.mark.parametrize("seed", range(8))
def test_offset_pose_is_the_distance_away_and_turned_by_the_angle(seed):
    moved = offset_pose(POSE, 20.0, 90.0, seed)
    assert math.hypot(moved[0] - POSE[0], moved[1] - POSE[1]) == pytest.approx(20.0, abs=1e-9)
    assert moved[2:5] == POSE[2:5]
    # 3.0 rad + 90 deg = 4.5708 rad, wrapped into (-pi, pi]: 4.5708 - 2 pi.
    assert moved[5] == pytest.approx(3.0 + math.pi / 2 - 2 * math.pi, abs=1e-12)
    assert offset_pose(POSE, 20.0, 90.0, seed) == moved


def test_offset_directions_cover_the_circle():
    angles = [math.atan2(p[1] - POSE[1], p[0] - POSE[0]) for p in (offset_pose(POSE, 1.0, 0.0, s) for s in range(200))]
    quadrants = np.histogram(angles, bins=4, range=(-math.pi, math.pi))[0]
    assert quadrants.min() >= 30  # 50 expected per quadrant of a uniform direction
    assert offset_pose(POSE, 0.0, 0.0, 3) == pytest.approx(POSE)


def test_hint_offsets_have_the_given_sigma_and_no_bias():
    draws = np.array([sample_hint((100.0, 200.0), 20.0, seed) for seed in range(4000)])
    offsets = draws - [100.0, 200.0]
    # Standard error of the mean 20 / sqrt(4000) = 0.32 m; of the standard deviation about 0.22 m.
    np.testing.assert_allclose(offsets.mean(axis=0), [0, 0], atol=1.3)
    np.testing.assert_allclose(offsets.std(axis=0), [20, 20], atol=1.0)
    assert abs(np.corrcoef(offsets.T)[0, 1]) < 0.06
    assert sample_hint((1.0, 2.0), 20.0, 7) == sample_hint((1.0, 2.0), 20.0, 7)
    assert sample_hint((1.0, 2.0), 0.0, 7) == (1.0, 2.0)


def test_what_each_start_gives_the_localizer():
    pose = start_from(StartSetting("pose"), POSE)
    assert pose.initial_pose == POSE and pose.hint_xy is None
    wrong = start_from(StartSetting("pose", offset_m=20.0, offset_deg=90.0, seed=1), POSE)
    assert wrong.initial_pose == offset_pose(POSE, 20.0, 90.0, 1)
    hint = start_from(StartSetting("hint", hint_sigma_m=20.0, seed=1), POSE)
    assert hint.initial_pose is None and hint.hint_xy == sample_hint(POSE[:2], 20.0, 1) and hint.hint_sigma_m == 20
    none = start_from(StartSetting("none"), None)
    assert none.initial_pose is None and none.hint_xy is None


def config(tmp_path: Path, **kwargs) -> ExperimentConfig:
    for name in ("r.bag", "m.pcd", "gt.tum"):
        (tmp_path / name).write_text("x")
    return ExperimentConfig(tmp_path / "out", tmp_path / "r.bag", tmp_path / "m.pcd", tmp_path / "gt.tum", **kwargs)


def test_launch_and_recorder_per_start(tmp_path):
    cfg = config(tmp_path)
    pose = start_from(cfg.start, POSE)
    args = launch_args(cfg, "global", cfg.global_map, None, pose.initial_pose)
    assert args["initial_pose"].startswith("[10, -5, 1.5,") and "global_search_timeout" not in args
    argv = recorder_args(cfg, tmp_path, pose)
    assert any(a.startswith("_initial_pose:=") for a in argv) and not any("hint" in a for a in argv)

    cfg = config(tmp_path, start=StartSetting("hint", hint_sigma_m=20.0), hint_topic="/gnss/hint")
    hint = start_from(cfg.start, POSE)
    args = launch_args(cfg, "grid_puzzle", cfg.global_map, tmp_path, hint.initial_pose)
    assert args["initial_pose"] == "[]" and args["global_search_timeout"] == cfg.start_search_timeout_s
    argv = recorder_args(cfg, tmp_path, hint)
    assert f"_hint:={[*hint.hint_xy, 20.0]}" in argv and "initialpose_hint:=/gnss/hint" in argv
    assert not any(a.startswith("_initial_pose:=") for a in argv)

    cfg = config(tmp_path, start=StartSetting("none"), global_search_timeout_s=3.0)
    args = launch_args(cfg, "global", cfg.global_map, None, None)
    assert args["initial_pose"] == "[]" and args["global_search_timeout"] == 3.0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--start", "hint", "--start-offset", "20", "90"], "use it with --start pose"),
        (["--start", "none", "--modes", "block_map"], "block_map mode starts its block server from a pose"),
        (["--start", "none", "--global-search-timeout", "0"], "needs --global-search-timeout > 0"),
        (["--start-offset", "-1", "0"], "distance must be >= 0"),
        (["--start", "hint", "--hint-sigma", "-2"], "--hint-sigma must be >= 0"),
    ],
)
def test_start_options_that_cannot_work_are_refused(tmp_path, argv, message):
    cfg = config(tmp_path)
    parser = argparse.ArgumentParser()
    experiment_command.add_arguments(parser)
    args = parser.parse_args(
        ["-o", str(tmp_path / "o"), "--bag", str(cfg.bag), "--map", str(cfg.global_map), "--ground-truth",
         str(cfg.ground_truth), *argv]
    )  # fmt: skip
    with pytest.raises(UserError, match=message):
        experiment_command.config_from_args(args).check()


def test_start_none_needs_no_ground_truth(tmp_path):
    cfg = config(tmp_path, start=StartSetting("none"))
    cfg.ground_truth = None
    cfg.check()
    cfg.start = StartSetting("hint")
    with pytest.raises(UserError, match="give the start pose"):
        cfg.check()


# A reference along x at 2 m/s with yaw 0.3 rad, poses every 0.5 s from t = 10 s (the first played scan).
REF_T = 10.0 + 0.5 * np.arange(21)
REFERENCE = make_trajectory(REF_T, np.stack([2 * (REF_T - 10), 0 * REF_T, 0 * REF_T], 1), yaw_quat(0.3 + 0 * REF_T))


def estimate(t, dxy, yaw):
    t = np.asarray(t, dtype=float)
    xyz = np.stack([2 * (t - 10) + dxy[0], 0 * t + dxy[1], 0 * t], 1)
    return make_trajectory(t, xyz, yaw_quat(np.full(len(t), yaw)))


def test_first_pose_time_and_error_against_the_reference_at_its_stamp():
    # First pose at 12.25 s (between two reference poses: the reference is linear, so interpolation is exact),
    # 3 m and 4 m off (5 m), turned to 0.8 rad (0.5 rad = 28.6479 deg from the reference).
    est = estimate([12.25, 12.5, 13.0], (3.0, 4.0), 0.8)
    found = first_pose(est, 10.0, REFERENCE, max_diff_s=0.3)
    assert found.stamp_s == 12.25 and found.after_s == pytest.approx(2.25)
    assert found.translation_error_m == pytest.approx(5.0, abs=1e-9)
    assert found.yaw_error_deg == pytest.approx(math.degrees(0.5), abs=1e-9)
    # Only 13.0 s came from an accepted match.
    accepted = first_pose(est, 10.0, REFERENCE, np.array([11.0, 13.0]), max_diff_s=0.3)
    assert accepted.stamp_s == 13.0 and accepted.after_s == pytest.approx(3.0)
    assert first_pose(est, 10.0, REFERENCE, np.array([11.0, 14.0])) is None
    # Without a reference there, the time still counts.
    lone = first_pose(estimate([30.0], (0, 0), 0.3), 10.0, REFERENCE)
    assert lone.after_s == 20.0 and lone.translation_error_m is None and lone.yaw_error_deg is None


def test_start_figures_keep_an_unknown_acceptance_apart_from_none():
    est = estimate([12.0, 12.5], (0.0, 0.0), 0.3)
    known = start_figures(est, 10.0, REFERENCE, np.array([12.5]), 0.05)
    assert known["first_pose"]["after_s"] == 2.0 and known["first_accepted_pose"]["after_s"] == 2.5
    assert known["first_accepted_pose"]["translation_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert "first_accepted_pose" not in start_figures(est, 10.0, REFERENCE, None, 0.05)
    assert start_figures(est, 10.0, REFERENCE, np.zeros(0), 0.05)["first_accepted_pose"] is None
    assert start_figures(est, None, REFERENCE, None, 0.05) is None


def test_yaw_difference_wraps_around_the_half_turn():
    ref, est = yaw_quat(np.radians([170.0, 10.0])), yaw_quat(np.radians([-170.0, -20.0]))
    np.testing.assert_allclose(yaw_difference_deg(ref, est), [20.0, 30.0], atol=1e-9)


def test_report_start_table():
    pose = {"stamp_s": 12.0, "after_s": 2.0, "translation_error_m": 0.123, "yaw_error_deg": 1.25}
    summary = {
        "start": {"mode": "hint", "hint_xy": [1.0, 2.0], "hint_sigma_m": 20.0},
        "modes": {
            "global": {"start": {"first_scan_stamp_s": 10.0, "first_pose": pose, "first_accepted_pose": None}},
            "grid_puzzle": {"start": {"first_scan_stamp_s": 10.0, "first_pose": pose}},
        },
    }
    lines = start_table(summary)
    assert lines[0] == "Start: no pose; a hint at (1.0, 2.0) m (sigma 20 m) on initialpose_hint."
    assert lines[4] == "| global map | 2.00 | 0.12 | 1.2 | never | – | – |"
    assert lines[5] == "| grid puzzle | 2.00 | 0.12 | 1.2 | – | – | – |"
