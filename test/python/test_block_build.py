"""End to end `gpm blocks` on synthetic keyframes: a known world of lattice points seen from a straight
trajectory, written as sensor-frame PCDs with a TUM pose file and a non-trivial extrinsic. The blocks
must hold exactly the world points seen by their keyframes, and the index must describe the files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from tf2_msgs.msg import TFMessage

from grid_puzzle_localization.blocks.store import read_block_index
from grid_puzzle_localization.cli import main
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array
from grid_puzzle_localization.ros.msgs.cloud import array_to_cloud
from grid_puzzle_localization.util.iteration import zip_equal

RADIUS = 6.05  # [m] a scan sees the world points within this planar distance of the robot
EXTRINSIC = (0.5, 0.0, 1.2, 0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # sensor 90 deg yawed, raised
XYZ32 = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])


def world() -> np.ndarray:
    # Lattice at voxel centres (0.1 + 0.4 i with a 0.2 m voxel): each voxel holds one world point.
    xs = 0.1 + 0.4 * np.arange(-12, 115)
    walls = [(x, y, z) for x in xs for y in (-3.1, 3.1) for z in (0.1, 0.5, 0.9)]
    return np.array(walls)


def robot_pose(k: int) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("z", 0.05 * k).as_matrix()
    pose[0, 3] = float(k)
    return pose


def sensor_pose(robot: np.ndarray) -> np.ndarray:
    extrinsic = np.eye(4)
    extrinsic[:3, :3] = Rotation.from_quat(EXTRINSIC[3:]).as_matrix()
    extrinsic[:3, 3] = EXTRINSIC[:3]
    return robot @ extrinsic


def seen(points: np.ndarray, robot: np.ndarray) -> np.ndarray:
    return np.linalg.norm(points[:, :2] - robot[:2, 3], axis=1) < RADIUS


@pytest.fixture
def keyframe_set(tmp_path: Path) -> tuple[Path, Path]:
    scans = tmp_path / "scans"
    scans.mkdir()
    points = world()
    lines = []
    for k in range(41):  # robot at x = 0 .. 40 m, 1 m apart
        robot = robot_pose(k)
        inverse = np.linalg.inv(sensor_pose(robot))
        local = points[seen(points, robot)] @ inverse[:3, :3].T + inverse[:3, 3]
        cloud = np.empty(len(local), dtype=XYZ32)
        cloud["x"], cloud["y"], cloud["z"] = local.T
        write_pcd(scans / f"{k}.pcd", cloud)
        q = Rotation.from_matrix(robot[:3, :3]).as_quat()
        lines.append(f"{0.5 * k!r} {robot[0, 3]!r} 0.0 0.0 {q[0]!r} {q[1]!r} {q[2]!r} {q[3]!r}")
    poses = tmp_path / "poses.tum"
    poses.write_text("\n".join(lines) + "\n")
    return scans, poses


BUILD = ["--size", "10", "--keyframe-spacing", "2", "--voxel", "0.2"]


def run_blocks(scans: Path, poses: Path, out: Path, *extra: str) -> int:
    args = ["blocks", str(out), "--keyframes", str(scans), "--poses", str(poses)]
    return main([*args, "--extrinsic", *map(repr, EXTRINSIC), *BUILD, *extra])


def write_bag(scans: Path, path: Path) -> None:
    """The keyframe set as a bag: clouds on `points` (frame lidar) stamped 0.5 k s, extrinsic on /tf_static."""
    tf = TransformStamped()
    tf.header.frame_id, tf.child_frame_id = "base_link", "lidar"
    tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = EXTRINSIC[:3]
    q = tf.transform.rotation
    q.x, q.y, q.z, q.w = EXTRINSIC[3:]
    with rosbag.Bag(str(path), "w") as bag:
        bag.write("/tf_static", TFMessage(transforms=[tf]), rospy.Time(0))
        for k in range(41):
            stamp = rospy.Time.from_sec(0.5 * k)
            bag.write("points", array_to_cloud(read_pcd(scans / f"{k}.pcd").points, "lidar", stamp), stamp)


def test_blocks_hold_the_points_their_keyframes_saw(keyframe_set, tmp_path):
    scans, poses = keyframe_set
    out = tmp_path / "blocks"
    assert run_blocks(scans, poses, out) == 0
    index = read_block_index(out)
    # Keyframes every 2 m; a candidate spans keyframes within S = 10 m of its first one; the four
    # candidates' centroids lie more than 0.5 S apart, so all are stored.
    groups = [range(0, 11, 2), range(12, 23, 2), range(24, 35, 2), range(36, 41, 2)]
    assert [b.extra["keyframes"] for b in index.blocks] == [len(g) for g in groups]
    points = world()
    covered = np.zeros(len(points), dtype=bool)
    for entry, group in zip_equal(index.blocks, groups):
        mask = np.zeros(len(points), dtype=bool)
        for k in group:
            mask |= seen(points, robot_pose(k))
        covered |= mask
        stored = xyz_array(read_pcd(out / entry.file).points)
        assert len(stored) == mask.sum() == entry.points
        distance, _ = cKDTree(points[mask]).query(stored)
        assert distance.max() < 1e-5  # float32 storage of map coordinates up to ~45 m
        assert entry.bytes == (out / entry.file).stat().st_size
        np.testing.assert_allclose(entry.bounds_min, stored.min(axis=0), atol=0)
        np.testing.assert_allclose(entry.bounds_max, stored.max(axis=0), atol=0)
        np.testing.assert_allclose(entry.centroid, points[mask].mean(axis=0), atol=1e-6)  # float32 scans
    assert index.map_points == covered.sum()
    centroids = np.loadtxt(out / "centroids.txt")
    np.testing.assert_array_equal(centroids[:, 0], np.arange(len(index.blocks)))
    np.testing.assert_array_equal(centroids[:, 1:], index.centroids())


def test_bag_input_builds_the_same_blocks(keyframe_set, tmp_path):
    scans, poses = keyframe_set
    write_bag(scans, tmp_path / "scans.bag")
    assert run_blocks(scans, poses, tmp_path / "from_pcd") == 0
    bag_args = ["blocks", str(tmp_path / "from_bag"), "--bag", str(tmp_path / "scans.bag"), "--trajectory", str(poses)]
    assert main([*bag_args, *BUILD]) == 0
    a, b = read_block_index(tmp_path / "from_pcd"), read_block_index(tmp_path / "from_bag")
    assert [e.points for e in a.blocks] == [e.points for e in b.blocks]
    np.testing.assert_allclose(a.centroids(), b.centroids(), atol=1e-9)
    np.testing.assert_allclose(b.params["extrinsic"], a.params["extrinsic"], atol=1e-12)  # read from /tf_static


def test_map_input_cuts_the_same_keyframes(keyframe_set, tmp_path):
    scans, poses = keyframe_set
    cloud = np.empty(len(world()), dtype=XYZ32)
    cloud["x"], cloud["y"], cloud["z"] = world().T
    write_pcd(tmp_path / "world.pcd", cloud)
    assert run_blocks(scans, poses, tmp_path / "from_pcd") == 0
    map_args = ["blocks", str(tmp_path / "from_map"), "--map", str(tmp_path / "world.pcd"), "--trajectory", str(poses)]
    assert main([*map_args, "--scan-radius", str(RADIUS), *BUILD]) == 0
    a, b = read_block_index(tmp_path / "from_pcd"), read_block_index(tmp_path / "from_map")
    assert [e.points for e in a.blocks] == [e.points for e in b.blocks]
    np.testing.assert_allclose(a.centroids(), b.centroids(), atol=1e-6)


def test_existing_output_needs_force(keyframe_set, tmp_path, capsys):
    scans, poses = keyframe_set
    out = tmp_path / "blocks"
    out.mkdir()
    (out / "old.txt").write_text("old")
    assert run_blocks(scans, poses, out) == 2
    assert "--force" in capsys.readouterr().err
    assert run_blocks(scans, poses, out, "--force") == 0
    assert not (out / "old.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocks", "poses.tum", "scans"]  # no temporaries left


def test_pose_count_mismatch_is_a_user_error(keyframe_set, tmp_path, capsys):
    scans, poses = keyframe_set
    poses.write_text("\n".join(poses.read_text().splitlines()[:-1]) + "\n")
    assert run_blocks(scans, poses, tmp_path / "blocks") == 2
    assert "40 poses but" in capsys.readouterr().err
