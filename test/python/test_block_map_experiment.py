"""block_map mode end to end: a tiny simulated courtyard, block maps stitched from its prior map along
the ground truth, block_map_server feeding the NDT localizer's cloud mode. The localized trajectory must
stay within 10 cm of the simulator's ground truth, and the storage table must describe the blocks."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

GPM = [sys.executable, str(Path(__file__).resolve().parents[2] / "scripts" / "gpm")]
SECONDS = 15.0  # of simulated walking (the platform rests the first 2 s)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """(the test's directory, the experiment's summary)."""
    d = tmp_path_factory.mktemp("block_map_experiment")
    sim = ["simulate", "courtyard", "--scale", "0.3", "--duration", str(SECONDS), "--seed", "0"]
    # In child processes, as a user runs them (the simulator's threads stay out of the test process).
    subprocess.run([*GPM, *sim, "-o", str(d / "scenario"), "--quiet"], check=True)
    # A new output directory, tiles and submaps kept elsewhere: the experiment creates the directory for its
    # block maps.
    experiment = ["experiment", str(d / "scenario"), "-o", str(d / "out"), "--modes", "block_map"]
    options = ["--tiles", str(d / "tiles"), "--submaps", str(d / "submaps"), "--block-size", "4"]
    subprocess.run([*GPM, *experiment, *options, "--ndt-threads", "2", "--settle", "1"], check=True)
    return d, json.loads((d / "out" / "summary.json").read_text())


def test_block_map_trajectory_stays_within_10_cm_of_ground_truth(run):
    _, summary = run
    ape = summary["modes"]["block_map"]["ape"]["translation_m"]
    assert ape["pairs"] >= 0.7 * SECONDS * 10  # 10 Hz sweeps; the first ones may wait for the map
    assert ape["max"] < 0.10


def test_storage_rows_for_all_four_maps(run):
    d, summary = run
    storage = summary["storage"]
    assert set(storage) == {"global_map", "tiles", "block_maps", "fixed_submaps"}
    assert storage["fixed_submaps"]["overlap_factor"] == 4.0  # 50 % overlap in x and y
    # The submaps went where --submaps said, not into the output directory.
    assert storage["fixed_submaps"]["files"] == len(list((d / "submaps").glob("*.pcd"))) > 0
    assert not list((d / "out").glob("submaps_L*"))
    assert storage["tiles"]["overlap_factor"] == 1.0
    blocks = storage["block_maps"]
    assert blocks["files"] >= 2 and blocks["overlap_factor"] >= 1.0
    assert blocks["mean_bytes_per_file"] == blocks["bytes"] / blocks["files"]
