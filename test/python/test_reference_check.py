"""tools/reference_check.py on the real HDL-32E pair (test/data/hdl32_pair): a reference that states the pair's motion
as two independent registrations measured it is consistent; one 1.5 m off is not, by about 1.5 m."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import reference_check  # noqa: E402

pytestmark = pytest.mark.skipif(
    not reference_check.NDT_ALIGN.is_file(), reason="needs the built ndt_align (make build, then source tools/env.sh)"
)


def pair_folder(tmp_path: Path, real_data: Path, motion: np.ndarray) -> tuple[Path, Path]:
    """Scans 0 (target) and 1 (source) of the HDL-32E pair, with KITTI poses I and ``motion``."""
    scans = tmp_path / "scans"
    scans.mkdir()
    shutil.copy(real_data / "hdl32_pair" / "251370668.pcd", scans / "0.pcd")
    shutil.copy(real_data / "hdl32_pair" / "251371071.pcd", scans / "1.pcd")
    poses = tmp_path / "poses.txt"
    poses.write_text("\n".join(" ".join(f"{v:.9g}" for v in m[:3].ravel()) for m in (np.eye(4), motion)) + "\n")
    return scans, poses


@pytest.fixture
def measured(real_data: Path) -> np.ndarray:
    return np.loadtxt(real_data / "hdl32_pair" / "T_target_source_small_gicp.txt")


def test_a_reference_that_agrees_with_registration_is_consistent(tmp_path, real_data, measured):
    rows, _ = reference_check.check(*pair_folder(tmp_path, real_data, measured), 0, 1)
    assert len(rows) == 1
    row = rows[0]
    assert row["consistent"] and not row["ambiguous"], row
    assert row["shift_m"] < 0.05  # the reference pair's own accuracy (test/data/SOURCES.md)
    assert row["registered_step_m"] == pytest.approx(np.linalg.norm(measured[:3, 3]), abs=0.05)


def test_a_reference_off_by_a_metre_and_a_half_is_not(tmp_path, real_data, measured):
    wrong = measured.copy()
    wrong[0, 3] += 1.5
    rows, trusted = reference_check.check(*pair_folder(tmp_path, real_data, wrong), 0, 1)
    row = rows[0]
    assert not row["consistent"], row
    assert row["shift_m"] == pytest.approx(1.5, abs=0.1)
    assert trusted == set()


def test_the_cached_check_runs_once_per_input_and_again_when_the_poses_change(
    tmp_path, real_data, measured, monkeypatch
):
    scans, poses = pair_folder(tmp_path, real_data, measured)
    calls = []
    real = reference_check.check
    monkeypatch.setattr(reference_check, "check", lambda *args: calls.append(args) or real(*args))
    first = reference_check.cached_check(scans, poses, 0, 1, tmp_path / "cache")
    assert reference_check.cached_check(scans, poses, 0, 1, tmp_path / "cache") == first
    assert len(calls) == 1 and first[0][0]["consistent"]
    wrong = measured.copy()
    wrong[0, 3] += 1.5
    wrong_poses = tmp_path / "wrong.txt"
    wrong_poses.write_text("\n".join(" ".join(f"{v:.9g}" for v in m[:3].ravel()) for m in (np.eye(4), wrong)))
    again = reference_check.cached_check(scans, wrong_poses, 0, 1, tmp_path / "cache")
    assert len(calls) == 2 and not again[0][0]["consistent"]


def test_the_map_check_says_how_far_the_map_moves_a_scan_from_its_reference_pose(tmp_path, real_data, measured):
    """The first scan of the pair is the map (pose I); the second's reference pose is the measured motion, then the
    same 1.5 m off: the map moves it by the reference's own accuracy, then by about 1.5 m."""
    wrong = measured.copy()
    wrong[0, 3] += 1.5
    shifts = []
    for motion in (measured, wrong):
        folder = tmp_path / f"run{len(shifts)}"
        folder.mkdir()
        scans, poses = pair_folder(folder, real_data, motion)
        rows = reference_check.map_check(scans, poses, 1, 1, scans / "0.pcd")
        assert [row["scan"] for row in rows] == [1] and rows[0]["status"] == "OK", rows
        shifts.append(rows[0]["map_shift_m"])
    assert shifts[0] < 0.05
    assert shifts[1] == pytest.approx(1.5, abs=0.1)
