"""`gpm import`: pose formats, scan selection and faults against closed forms, errors naming their input, and a
simulated scenario exported to scans + poses and imported back into the same experiment inputs."""

from __future__ import annotations

import filecmp
from pathlib import Path

import numpy as np
import pytest
import rosbag
import yaml
from scipy.spatial.transform import Rotation

from grid_puzzle_localization import cli
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.scenario import read_scenario
from grid_puzzle_localization.pcd import read_pcd, write_pcd
from grid_puzzle_localization.recordings.poses import read_poses
from grid_puzzle_localization.recordings.selection import Selection, plan
from grid_puzzle_localization.ros.msgs.cloud import cloud_to_array
from grid_puzzle_localization.sim.scenario import ScenarioConfig, generate


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    poses[:, :3, 3] = rng.uniform(-100, 100, (n, 3))
    return poses


def write_kitti(path: Path, poses: np.ndarray) -> Path:
    np.savetxt(path, poses[:, :3, :].reshape(len(poses), 12), fmt="%.17g")
    return path


# ---- pose files ----


def test_kitti_tum_and_matrix_files_give_the_same_poses(tmp_path):
    poses = random_poses(7)
    times = 100.0 + 0.5 * np.arange(7)
    quat = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    tum = np.column_stack([times, poses[:, :3, 3], quat])
    np.savetxt(tmp_path / "p.tum", tum, fmt="%.17g", header="t x y z qx qy qz qw")
    (tmp_path / "p.mat").write_text(
        "\n\n".join("\n".join(" ".join(f"{v:.17g}" for v in row) for row in p) for p in poses)
    )
    from_kitti, no_times = read_poses(write_kitti(tmp_path / "p.txt", poses), "kitti")
    from_tum, tum_times = read_poses(tmp_path / "p.tum", "tum")
    from_matrix, _ = read_poses(tmp_path / "p.mat", "matrix")
    assert no_times is None
    np.testing.assert_array_equal(tum_times, times)
    np.testing.assert_array_equal(from_kitti, poses)
    np.testing.assert_array_equal(from_matrix, poses)
    np.testing.assert_allclose(from_tum, poses, atol=1e-12)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: p[:, :3, :3] * 1.01, r"p\.txt:3: pose 2 is not a rigid transform: rotation part"),
        (lambda p: p[:, :3, :3] @ np.diag([1.0, 1.0, -1.0]), r"p\.txt:3: pose 2 .* det -1"),
        (lambda p: np.full((3, 3), np.nan), r"p\.txt:3: pose 2 .* NaN"),
    ],
)
def test_poses_that_are_not_rigid_transforms_are_refused(tmp_path, change, message):
    poses = random_poses(4)
    poses[2, :3, :3] = change(poses[2:3])[0]
    with pytest.raises(UserError, match=message):
        read_poses(write_kitti(tmp_path / "p.txt", poses), "kitti")


def test_a_line_of_the_wrong_width_names_its_format(tmp_path):
    (tmp_path / "p.tum").write_text("# t x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n2 0 0\n")
    expected = r"p\.tum:3: a tum line has 8 numbers \(t tx ty tz qx qy qz qw\), found 3"
    with pytest.raises(UserError, match=expected):
        read_poses(tmp_path / "p.tum", "tum")
    with pytest.raises(UserError, match=expected):
        read_tum(tmp_path / "p.tum")


# ---- which scans are mapped and played ----


def test_map_every_third_plays_the_others():
    p = plan(Selection(first=50, last=215, map_every=3), np.arange(300) * 0.5)
    np.testing.assert_array_equal(p.mapped, np.arange(50, 216, 3))
    np.testing.assert_array_equal(p.played, [k for k in range(50, 216) if (k - 50) % 3])
    assert len(p.mapped) + len(p.played) == 166


def test_gaps_cut_exactly_the_scans_inside_them():
    times = 10.0 + 0.1 * np.arange(200)  # scan k at 10 + 0.1 k s
    p = plan(Selection(map_range=(0, 9), gaps=((2.0, 2.0), (8.0, 4.0))), times)
    t0 = times[10]  # the first played scan
    expected_cut = [k for k in range(10, 200) if 2.0 <= times[k] - t0 < 4.0 or 8.0 <= times[k] - t0 < 12.0]
    np.testing.assert_array_equal(p.cut, expected_cut)
    assert len(expected_cut) == 60
    assert np.diff(times[p.played]).max() == pytest.approx(4.1)


def test_drop_fraction_drops_that_many_scans_never_the_first_and_is_seeded():
    times = np.arange(1000) * 0.1
    a = plan(Selection(play="all", map_every=10, drop_fraction=0.1, seed=3), times)
    b = plan(Selection(play="all", map_every=10, drop_fraction=0.1, seed=3), times)
    c = plan(Selection(play="all", map_every=10, drop_fraction=0.1, seed=4), times)
    assert len(a.dropped) == 100 and len(a.played) == 900 and a.played[0] == 0
    np.testing.assert_array_equal(a.dropped, b.dropped)
    assert not np.array_equal(a.dropped, c.dropped)
    assert np.intersect1d(a.dropped, a.played).size == 0


def test_selection_errors_name_the_option():
    times = np.arange(10.0)
    with pytest.raises(UserError, match="--map-every N, --map-range A B, or --map FILE"):
        plan(Selection(), times)
    with pytest.raises(UserError, match="--last 10 must satisfy"):
        plan(Selection(last=10, map_every=2), times)
    with pytest.raises(UserError, match="--drop-fraction must be in"):
        plan(Selection(map_every=2, drop_fraction=1.0), times)
    with pytest.raises(UserError, match="no scan is left to play"):
        plan(Selection(map_every=1), times)


# ---- bad recordings: a clear error naming the input, no output left behind ----


@pytest.fixture
def recording(tmp_path) -> Path:
    """Five small scans on a line, 1 m and 0.1 s apart, with KITTI poses and times."""
    scans = tmp_path / "rec" / "scans"
    scans.mkdir(parents=True)
    rng = np.random.default_rng(1)
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    for k in range(5):
        cloud = np.zeros(200, dtype)
        for name in dtype.names:
            cloud[name] = rng.uniform(-5, 5, 200)
        write_pcd(scans / f"{k}.pcd", cloud)
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, 0, 3] = np.arange(5.0)
    write_kitti(tmp_path / "rec" / "poses.txt", poses)
    np.savetxt(tmp_path / "rec" / "times.txt", 50.0 + 0.1 * np.arange(5), fmt="%.9f")
    return tmp_path / "rec"


def run_import(rec: Path, out: Path, *extra: str) -> int:
    args = ["import", str(rec / "scans"), str(rec / "poses.txt"), "--times", str(rec / "times.txt"), "-o", str(out)]
    return cli.main([*args, "--quiet", *extra])


def test_counts_that_disagree_are_refused(recording, tmp_path, capsys):
    (recording / "times.txt").write_text("1\n2\n3\n4\n")
    assert run_import(recording, tmp_path / "out", "--map-every", "2") == 2
    err = capsys.readouterr().err
    assert "5 scan files, 5 poses, 4 times" in err and "--last" in err
    assert not (tmp_path / "out").exists()
    assert run_import(recording, tmp_path / "out", "--map-every", "2", "--last", "3") == 0


def test_unreadable_scans_are_named(recording, tmp_path, capsys):
    scan = recording / "scans" / "3.pcd"
    scan.write_bytes(scan.read_bytes()[:-40])
    assert run_import(recording, tmp_path / "out", "--map-every", "2") == 2
    assert f"unreadable scan: {scan}: truncated" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_kitti_bin_scans_of_the_wrong_size_are_named(tmp_path, capsys):
    rec = tmp_path / "rec"
    (rec / "scans").mkdir(parents=True)
    np.arange(16, dtype="<f4").tofile(rec / "scans" / "000000.bin")
    np.arange(15, dtype="<f4").tofile(rec / "scans" / "000001.bin")
    write_kitti(rec / "poses.txt", np.tile(np.eye(4), (2, 1, 1)))
    (rec / "times.txt").write_text("0\n0.1\n")
    assert run_import(rec, tmp_path / "out", "--map-every", "2", "--play", "all") == 2
    assert "000001.bin: 60 bytes is not a whole number of KITTI records" in capsys.readouterr().err


def test_map_from_scans_is_their_voxel_filter(recording, tmp_path):
    assert run_import(recording, tmp_path / "out", "--map-every", "2", "--map-voxel", "0.5") == 0
    mapped = []
    for k in (0, 2, 4):  # the identity-rotation poses shift scan k by k metres along x
        cloud = read_pcd(recording / "scans" / f"{k}.pcd").points
        mapped.append(np.column_stack([cloud["x"].astype(np.float64) + k, cloud["y"], cloud["z"]]))
    points = np.concatenate(mapped)
    keys, inverse = np.unique(np.floor(points / 0.5).astype(np.int64), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    expected = (
        np.stack([np.bincount(inverse, weights=points[:, a]) for a in range(3)], 1) / np.bincount(inverse)[:, None]
    )
    got = read_pcd(tmp_path / "out" / "global_map.pcd").points
    got = np.column_stack([got["x"], got["y"], got["z"]]).astype(np.float64)
    assert len(got) == len(keys)
    np.testing.assert_allclose(got[np.lexsort(got.T[::-1])], expected[np.lexsort(expected.T[::-1])], atol=1e-5)
    meta = yaml.safe_load((tmp_path / "out" / "scenario.yaml").read_text())
    assert meta["mapping_run"]["scans"] == ["0.pcd", "2.pcd", "4.pcd"]
    assert meta["localization_run"]["scans_played"] == 2


# ---- round trip: a simulated scenario out as scans + poses and back in ----


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("roundtrip") / "sim"
    generate(ScenarioConfig(world="courtyard", seed=7, scale=0.25, duration=4.0, map_leaf=0.1), out, progress=False)
    return out


def export(scenario: Path, out: Path) -> tuple[np.ndarray, list]:
    """The scenario's scans as PCD files (lidar frame), base_link poses at their stamps (KITTI) and their times;
    returns the base -> lidar extrinsic and the original messages."""
    (out / "scans").mkdir(parents=True)
    truth = read_tum(scenario / "ground_truth.tum")
    with rosbag.Bag(str(scenario / "scenario.bag")) as bag:
        msgs = [m for _, m, _ in bag.read_messages(topics=["points"])]
        tf = next(m for _, m, _ in bag.read_messages(topics=["/tf_static"])).transforms[0].transform
    stamps = np.array([m.header.stamp.to_nsec() for m in msgs])
    rows = [int(np.argmin(np.abs(truth.t - s * 1e-9))) for s in stamps]
    assert np.abs(truth.t[rows] - stamps * 1e-9).max() < 1e-6  # sweeps start on ground-truth samples
    poses = np.tile(np.eye(4), (len(msgs), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(truth.quat[rows]).as_matrix()
    poses[:, :3, 3] = truth.xyz[rows]
    for k, msg in enumerate(msgs):
        write_pcd(out / "scans" / f"{k:06d}.pcd", cloud_to_array(msg))
    write_kitti(out / "poses.txt", poses)
    (out / "times.txt").write_text("".join(f"{s // 10**9}.{s % 10**9:09d}\n" for s in stamps.tolist()))
    extrinsic = [tf.translation.x, tf.translation.y, tf.translation.z, *(getattr(tf.rotation, a) for a in "xyzw")]
    return np.array(extrinsic), msgs


def test_simulated_scenario_exported_and_imported_gives_the_same_experiment_inputs(simulated, tmp_path):
    extrinsic, originals = export(simulated, tmp_path / "rec")
    out = tmp_path / "imported"
    extra = ["--map", str(simulated / "global_map.pcd"), "--extrinsic", *map(repr, extrinsic.tolist())]
    assert run_import(tmp_path / "rec", out, *extra) == 0
    before, after = read_scenario(simulated), read_scenario(out)
    assert filecmp.cmp(before.global_map, after.global_map, shallow=False)
    with rosbag.Bag(str(after.bag)) as bag:
        clouds = [m for _, m, _ in bag.read_messages(topics=["points"])]
        tf = [m for _, m, _ in bag.read_messages(topics=["/tf_static"])]
    assert len(clouds) == len(originals) == 40
    for ours, theirs in zip(clouds, originals):
        assert ours.header.stamp == theirs.header.stamp and ours.header.frame_id == theirs.header.frame_id
        assert ours.fields == theirs.fields and ours.data == theirs.data and ours.width == theirs.width
    assert tf[0].transforms[0].transform.translation.z == pytest.approx(extrinsic[2])
    truth, imported = read_tum(before.ground_truth), read_tum(after.ground_truth)
    stamps = np.array([m.header.stamp.to_sec() for m in originals])
    np.testing.assert_allclose(imported.t, stamps, atol=1e-6)
    rows = np.searchsorted(truth.t, stamps - 1e-6)
    np.testing.assert_allclose(imported.xyz, truth.xyz[rows], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(imported.quat * truth.quat[rows], axis=1)), 1.0, atol=1e-9)
    # the experiment starts both at the same pose
    assert imported.t[0] == pytest.approx(truth.t[0], abs=1e-6)


def test_imported_scenario_gives_the_same_experiment_figures(simulated, tmp_path):
    # The localizer on the original scenario and on its import: the same scans, map and start pose (the import
    # carries no IMU, which the localizer does not need), so the same accuracy within a few millimetres.
    extrinsic, _ = export(simulated, tmp_path / "rec")
    extra = ["--map", str(simulated / "global_map.pcd"), "--extrinsic", *map(repr, extrinsic.tolist())]
    assert run_import(tmp_path / "rec", tmp_path / "imported", *extra) == 0
    ape = {}
    for name, scenario in (("original", simulated), ("imported", tmp_path / "imported")):
        argv = [
            "experiment",
            str(scenario),
            "-o",
            str(tmp_path / f"run_{name}"),
            "--modes",
            "global",
            "--settle",
            "1.5",
            "--empty-map-seconds",
            "0",  # accuracy only: no empty-map run for the memory floor
        ]
        assert cli.main(argv) == 0
        summary = yaml.safe_load((tmp_path / f"run_{name}" / "summary.json").read_text())
        ape[name] = summary["modes"]["global"]["ape"]["translation_m"]
    assert ape["imported"]["pairs"] >= 35 and ape["original"]["pairs"] >= 35
    assert ape["original"]["rmse"] < 0.1 and ape["imported"]["rmse"] < 0.1
    assert abs(ape["imported"]["rmse"] - ape["original"]["rmse"]) < 0.01
