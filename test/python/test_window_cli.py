"""`gpm window` output against Table I ranges and the directory listing."""

import json

import pytest
from fixtures.synthetic_tiles import write_tiles
from tile_truth import brute_force_window_files

from grid_puzzle_localization.cli import main


def run_window(capsys, *argv):
    assert main(["window", *argv]) == 0
    return json.loads(capsys.readouterr().out)


def test_heading_down_left_without_tiles(capsys):
    out = run_window(
        capsys, "--grid-size", "2", "--n", "1", "--k", "2", "--x", "-3", "--y", "-3", "--prev-x", "1", "--prev-y", "1"
    )
    assert out["center_tile"] == [-2, -2] and out["center"] == [-3.0, -3.0]
    assert out["theta_deg"] == pytest.approx(-135.0) and out["sector"] == 5
    assert out["u_range"] == [-3, 1] and out["v_range"] == [-3, 1]
    assert len(out["tiles"]) == out["tiles_in_window"] == 25
    assert {"key": [-5, -5], "file": "-9.0_-9.0.pcd"} in out["tiles"]


def test_existing_tiles_only_with_tiles_dir(capsys, tmp_path):
    keys = [(i, j) for i in range(-4, 4) for j in range(-4, 4) if (i + j) % 3]
    write_tiles(tmp_path, keys, 0.5, count=3)
    out = run_window(
        capsys, "--tiles", str(tmp_path), "--grid-size", "0.5", "--preset", "courtyard", "--x", "0.1", "--y", "0.1"
    )
    assert out["sector"] == -1 and out["theta_rad"] is None and out["n"] == 17
    b = out["bounds"]
    truth = brute_force_window_files(tmp_path, (b["i_min"], b["i_max"], b["j_min"], b["j_max"]), 0.5)
    assert {tuple(t["key"]) for t in out["tiles"]} == truth and out["existing_only"]


def test_short_move_is_reported_and_gives_the_plain_square(capsys):
    out = run_window(
        capsys, "--grid-size", "2", "--n", "1", "--k", "5", "--x", "0.5", "--y", "0", "--prev-x", "0", "--prev-y", "0"
    )
    assert out["sector"] == -1 and "update distance" in out["note"]


def test_errors_exit_2(capsys, tmp_path):
    assert main(["window", "--x", "0", "--y", "0"]) == 2
    assert main(["window", "--grid-size", "2", "--x", "0", "--y", "0", "--prev-x", "1"]) == 2
    assert main(["window", "--tiles", str(tmp_path / "missing"), "--grid-size", "2", "--x", "0", "--y", "0"]) == 2
    assert "does not exist" in capsys.readouterr().err
