"""The prior map's displacement (sim/map_drift.py) against closed forms, and `gpm map-drift` end to end."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from grid_puzzle_localization import cli
from grid_puzzle_localization.evaluation.trajectory import make_trajectory, read_tum
from grid_puzzle_localization.sim.map_drift import map_displacement, split_errors
from grid_puzzle_localization.sim.scenario import ScenarioConfig, generate
from grid_puzzle_localization.sim.trajectory import RATE, Trajectory

TINY = ScenarioConfig(world="courtyard", seed=7, scale=0.25, duration=1.0, map_leaf=0.2)


def still(position, yaw: float, seconds: float = 10.0) -> Trajectory:
    n = int(seconds * RATE) + 1
    quat = np.tile(Rotation.from_euler("z", yaw).as_quat(), (n, 1))
    return Trajectory(np.tile(np.asarray(position, dtype=np.float64), (n, 1)), quat, np.array([0, 1]))


def test_a_shifted_map_displaces_every_position_by_the_shift():
    truth = still([5.0, -3.0, 0.5], 0.4)
    estimate = still([5.03, -3.02, 0.51], 0.4)
    positions = np.array([[5.0, -3.0, 0.0], [15.0, 2.0, 1.0], [200.0, 0.0, 0.0]])
    d = map_displacement(truth, estimate, positions, radius=25.0)
    np.testing.assert_allclose(d[:2], [[0.03, -0.02, 0.01]] * 2, atol=1e-12)
    assert np.isnan(d[2]).all()  # no mapping sweep within 25 m: unknown, not zero


def test_a_yaw_drift_turns_the_map_about_the_mapping_pose():
    psi = 3e-4
    truth, estimate = still([1.0, 2.0, 0.0], 0.0), still([1.0, 2.0, 0.0], psi)
    p = np.array([[21.0, 2.0, 0.0], [1.0, -8.0, 3.0]])
    rel = p - [1.0, 2.0, 0.0]
    expected = Rotation.from_euler("z", psi).apply(rel) - rel
    np.testing.assert_allclose(map_displacement(truth, estimate, p), expected, atol=1e-12)


def test_split_errors_takes_the_map_displacement_out_of_the_error():
    t = np.arange(5.0)
    truth = np.column_stack([t, np.zeros(5), np.zeros(5)])
    displacement = np.tile([0.03, 0.0, 0.0], (5, 1))
    own = np.array([[0.0, 0.01, 0.0]] * 4 + [[0.0, 0.05, 0.0]])
    track = make_trajectory(t, truth + displacement + own, np.tile([0.0, 0.0, 0.0, 1.0], (5, 1)))
    split = split_errors(truth, track, displacement)
    assert split.map_displacement.rmse == pytest.approx(0.03)
    assert split.tracker.max == pytest.approx(0.05)
    assert split.tracker.rmse == pytest.approx(np.sqrt((4 * 0.01**2 + 0.05**2) / 5))
    assert split.against_truth.max == pytest.approx(np.hypot(0.03, 0.05))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("drift") / "tiny"
    generate(TINY, out, progress=False)
    return out


def test_scenario_yaml_gives_back_the_configuration_it_was_made_with(tiny):
    parameters = yaml.safe_load((tiny / "scenario.yaml").read_text())["parameters"]
    assert ScenarioConfig.from_parameters(parameters).resolved() == TINY.resolved()


def test_the_ground_truth_itself_is_off_by_exactly_the_map_displacement(tiny, capsys):
    assert cli.main(["map-drift", str(tiny), str(tiny / "ground_truth.tum")]) == 0
    rows = [line.split("|")[1:-1] for line in capsys.readouterr().out.splitlines()[2:]]
    ground_truth = rows[1]
    assert ground_truth[2].strip() == "0.00 / 0.00"  # against itself
    assert ground_truth[3] == ground_truth[4]  # all that is left is the map's displacement
    rmse, peak = (float(v) for v in ground_truth[3].split("/"))
    bounds = TINY.drift
    assert 0.0 < rmse <= peak <= 100 * (bounds.horizontal + bounds.vertical + 25.0 * (bounds.yaw + 2 * bounds.tilt))
    assert len(read_tum(tiny / "ground_truth.tum")) == int(ground_truth[1])


def test_a_recording_that_was_not_simulated_is_a_clear_error(tiny, tmp_path, capsys):
    (tmp_path / "rec").mkdir()
    for name in ("scenario.bag", "global_map.pcd"):
        (tmp_path / "rec" / name).write_bytes((tiny / name).read_bytes())
    assert cli.main(["map-drift", str(tmp_path / "rec")]) == 2
    assert "is not a simulated scenario" in capsys.readouterr().err


def test_a_trajectory_of_another_time_span_is_a_clear_error(tiny, tmp_path, capsys):
    rows = [line.split() for line in (tiny / "ground_truth.tum").read_text().splitlines() if line[:1] != "#"]
    shifted = [f"{float(v[0]) + 1e6:.9f} " + " ".join(v[1:]) for v in rows]
    other = tmp_path / "other_run.tum"
    other.write_text("\n".join(shifted) + "\n")
    assert cli.main(["map-drift", str(tiny), str(other)]) == 2
    err = capsys.readouterr().err
    assert "other_run.tum" in err and "is it a run of" in err
