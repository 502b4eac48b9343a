"""tools/experiment_tracking.py without ROS playback: the straight-part selection on hand-counted keyframes, and the
kitti00_far variants (what each imports and how each starts), the map fit on the real HDL-32E pair, and the resource
figures of a run's summary."""

from __future__ import annotations

import shutil

import experiment_tracking as et
import numpy as np
import pytest
import reference_check

from grid_puzzle_localization.evaluation.repeats import median_resources, repeat_spread
from grid_puzzle_localization.evaluation.trajectory import make_trajectory
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array, xyz_records


def test_straight_parts_leave_out_each_turn_and_its_margin():
    keyframes = np.arange(770, 801)
    # The turn 777-791 widened by 3 keyframes: 774-794 out, 770-773 and 795-800 in.
    expected = (keyframes < 774) | (keyframes > 794)
    np.testing.assert_array_equal(et.straight(keyframes, turns=((777, 791),), margin=3), expected)
    np.testing.assert_array_equal(
        et.straight(keyframes, turns=((777, 791),), margin=0), (keyframes < 777) | (keyframes > 791)
    )


def test_straight_parts_of_the_whole_data_set():
    keyframes = np.concatenate([np.arange(696, 948), np.arange(1042, 1351)])
    kept = et.straight(keyframes)
    # Turn lengths 15, 7, 14, 6 and 8 keyframes, each widened by 2 x 3: 50 + 30 = 80 keyframes out.
    assert kept.sum() == len(keyframes) - 80
    assert not kept[keyframes == 774].any() and kept[keyframes == 773].all()
    assert not kept[keyframes == 1234].any() and kept[keyframes == 1235].all()


def test_each_stretch_runs_six_variants_on_two_imports():
    for name, (first, last, gap_at) in et.STRETCHES.items():
        stem = f"kitti_{name}"
        variants = {v: et.VARIANTS[v] for v in et.SETS["real"] if v.startswith(stem + "_") or v == stem}
        assert len(variants) == 6
        assert {v.scenario for v in variants.values()} == {stem, f"{stem}_drop20_gap8"}
        base = et.VARIANTS[stem].command
        assert (
            base[0] == "import"
            and base[base.index("--first") + 1 : base.index("--last") + 2] == (str(first), "--last", str(last))
            and base[-2:] == ("--map-every", "3")
        )
        thinned = et.VARIANTS[f"{stem}_drop20_gap8"].command
        assert thinned[: len(base)] == base and thinned[len(base) :] == (
            "--drop-fraction",
            "0.2",
            "--seed",
            "0",
            "--gap",
            f"{gap_at:g}",
            "8",
        )
        for v in variants.values():
            assert v.experiment[:2] == ("--preset", "urban")
        assert et.VARIANTS[f"{stem}_offset20_90"].experiment[2:] == ("--start-offset", "20", "90")
        assert et.VARIANTS[f"{stem}_hint20"].experiment[2:] == ("--start", "hint", "--hint-sigma", "20")
        assert et.VARIANTS[f"{stem}_none"].experiment[2:] == ("--start", "none")
        campus = et.VARIANTS[f"{stem}_none_campus"]
        assert campus.campus and campus.experiment == et.VARIANTS[f"{stem}_none"].experiment
        assert [v for v, k in variants.items() if k.campus] == [f"{stem}_none_campus"]
    assert not any(v.startswith("mulran") for v in et.VARIANTS)


def _write_xyz(path, xyz):
    write_pcd(path, xyz_records(np.asarray(xyz, dtype=np.float32)))


def test_the_campus_map_surrounds_the_stretch_with_its_empty_inside(tmp_path, monkeypatch):
    """A campus of two 25 m tiles: a ring road of radius 200 m about (1000, -500) (its largest empty disc is centred
    there) and an empty tile; a stretch map of two blobs whose bounding box is centred at (30, 40). The campus moves by
    (30, 40) - (1000, -500), the stretch stays, every point is kept."""
    angles = np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
    ring = np.stack([1000.0 + 200.0 * np.cos(angles), -500.0 + 200.0 * np.sin(angles), np.zeros_like(angles)], axis=1)
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    _write_xyz(tiles / "0_0.pcd", ring)
    _write_xyz(tiles / "0_1.pcd", np.empty((0, 3)))
    stretch = np.array([[0.0, 0.0, 1.0], [60.0, 80.0, 2.0], [10.0, 20.0, 3.0]])
    _write_xyz(tmp_path / "stretch.pcd", stretch)
    monkeypatch.setattr(et, "CAMPUS", tiles)
    out = et.campus_map(tmp_path / "stretch.pcd", tmp_path / "campus.pcd")
    merged = xyz_array(read_pcd(out).points)
    assert len(merged) == len(stretch) + len(ring)
    np.testing.assert_allclose(merged[: len(stretch)], stretch, atol=1e-5)
    shift = np.array([30.0 - 1000.0, 40.0 + 500.0, 0.0])
    # The empty disc's centre is found on CAMPUS_CELL_M cells: within a cell of the ring's centre.
    np.testing.assert_allclose(merged[len(stretch) :], ring + shift, atol=et.CAMPUS_CELL_M)
    moved = merged[len(stretch) :, :2] - [30.0, 40.0]
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), 200.0, atol=et.CAMPUS_CELL_M)
    # A stretch that reaches the ring is refused, naming its map.
    _write_xyz(tmp_path / "wide.pcd", [[0.0, 0.0, 0.0], [0.0, 380.0, 0.0]])
    with pytest.raises(RuntimeError, match=r"wide\.pcd reaches within"):
        et.campus_map(tmp_path / "wide.pcd", tmp_path / "wide_campus.pcd")


@pytest.mark.skipif(
    not reference_check.NDT_ALIGN.is_file(), reason="needs the built ndt_align (make build, then source tools/env.sh)"
)
@pytest.mark.parametrize("off_m", [0.0, 1.5])
def test_the_map_fit_is_how_far_the_map_moves_each_played_scan_from_its_reference(
    tmp_path, real_data, off_m, monkeypatch
):
    """A data set laid out as kitti00_far from the real HDL-32E pair: scan 0 is the map at pose I, scan 1 is played
    at the pair's motion as two independent registrations measured it, then the same 1.5 m off. The map fits it within
    the reference pair's own accuracy (test/data/SOURCES.md), then about 1.5 m from its reference."""
    motion = np.loadtxt(real_data / "hdl32_pair" / "T_target_source_small_gicp.txt")
    motion[0, 3] += off_m
    data = tmp_path / "kitti"
    (data / "scans").mkdir(parents=True)
    shutil.copy(real_data / "hdl32_pair" / "251370668.pcd", data / "scans" / "000000.pcd")
    shutil.copy(real_data / "hdl32_pair" / "251371071.pcd", data / "scans" / "000001.pcd")
    (data / "poses_kitti.txt").write_text(
        "\n".join(" ".join(f"{v:.9g}" for v in m[:3].ravel()) for m in (np.eye(4), motion)) + "\n"
    )
    (data / "times.txt").write_text("0.0\n0.1\n")
    monkeypatch.setattr(et, "KITTI", data)
    fit = et.map_fit(data / "scans" / "000000.pcd", np.array([0.1]))
    assert fit.figures["map_fit_translation_rmse_m"] == pytest.approx(off_m, abs=0.05)
    assert fit.figures["map_fit_translation_max_m"] == fit.figures["map_fit_translation_rmse_m"]
    assert fit.figures["map_fit_scans_over_1m"] == (1 if off_m > 1.0 else 0)
    # Where the map puts the scan: the pair's own motion (the independent registrations), whatever the reference says.
    truth = np.loadtxt(real_data / "hdl32_pair" / "T_target_source_small_gicp.txt")
    assert fit.poses.t.tolist() == [0.1]
    np.testing.assert_allclose(fit.poses.xyz[0], truth[:3, 3], atol=0.05)


def test_resource_figures_are_medians_over_the_runs_and_of_each_rounds_ratio():
    def run(cpu: float, rss_mib: float) -> dict:
        metrics = {"cpu_percent": cpu, "rss_bytes": rss_mib * 2**20, "pss_bytes": 0.0, "uss_bytes": 0.0}
        stats = {m: {"mean": v, "median": v, "p95": v, "max": v} for m, v in metrics.items()}
        return {protocol: {"processes": ["p"], **stats} for protocol in ("paper", "total")}

    per_repeat = {
        "global": [run(50.0, 100.0), run(60.0, 100.0), run(40.0, 100.0)],
        "grid_puzzle": [run(45.0, 70.0), run(48.0, 60.0), run(44.0, 90.0)],
    }
    summary = {
        "modes": {mode: {"resources": median_resources(runs)} for mode, runs in per_repeat.items()},
        "repeats": {"count": 3, "spread": repeat_spread(per_repeat, "global")},
    }
    grid = et.resource_figures(summary, "grid_puzzle")
    assert grid["repeats"] == 3
    # Medians of the runs' means: 45 % and 70 MiB; of the rounds' ratios 0.9, 0.8, 1.1 and 0.7, 0.6, 0.9.
    assert grid["paper"] == {"cpu_percent": 45.0, "rss_mib": 70.0, "cpu_vs_global": 0.9, "rss_vs_global": 0.7}
    assert et.resource_figures(summary, "global")["total"]["cpu_vs_global"] is None


def test_the_path_length_is_summed_along_the_reference_between_the_played_scans():
    t = np.arange(10.0)
    xyz = np.column_stack([3.0 * t, 4.0 * t, np.zeros(10)])  # 5 m a second
    reference = make_trajectory(t, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (10, 1)), "reference")
    assert et.path_length(reference, np.array([2.0, 5.5, 7.0])) == pytest.approx(25.0)
    assert et.path_length(reference, np.array([])) == 0.0
