"""`gpm simulate` end to end on a tiny scenario: files, bag contents, determinism, prior-map accuracy, errors."""

import filecmp
from dataclasses import replace

import numpy as np
import pytest
import rosbag
import yaml

from grid_puzzle_localization import cli
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd
from grid_puzzle_localization.sim import scenario, worlds
from grid_puzzle_localization.sim.lidar import POINT_DTYPE, Mount, SweepSimulator
from grid_puzzle_localization.sim.mapping import DriftBounds, drifted
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.scenario import FILES, MOUNTS, ScenarioConfig, generate
from grid_puzzle_localization.sim.sensors import get_sensor
from grid_puzzle_localization.sim.trajectory import localization_trajectory, mapping_trajectory
from grid_puzzle_localization.util.iteration import pairwise, zip_equal

TINY = ScenarioConfig(world="courtyard", seed=7, scale=0.25, duration=1.0, map_leaf=0.2)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    base = tmp_path_factory.mktemp("sim")
    generate(TINY, base / "a", progress=False)
    generate(TINY, base / "b", progress=False)
    return base


def test_same_seed_gives_byte_identical_files(tiny, tmp_path):
    for name in FILES:
        assert filecmp.cmp(tiny / "a" / name, tiny / "b" / name, shallow=False), name
    a, b = worlds.make_world("courtyard", 7, 0.25).mesh, worlds.make_world("courtyard", 8, 0.25).mesh
    assert a.vertices.shape != b.vertices.shape or not np.array_equal(a.vertices, b.vertices)


def test_thread_count_does_not_change_the_output(tiny, tmp_path):
    generate(replace(TINY, threads=1), tmp_path / "one", progress=False)
    generate(replace(TINY, threads=3), tmp_path / "three", progress=False)
    for name in FILES:
        assert filecmp.cmp(tiny / "a" / name, tmp_path / "one" / name, shallow=False), name
        assert filecmp.cmp(tiny / "a" / name, tmp_path / "three" / name, shallow=False), name


def test_movers_are_in_the_scans_but_not_in_the_map(tiny, tmp_path):
    meta = yaml.safe_load((tiny / "a" / "scenario.yaml").read_text())
    assert meta["movers"] == {"pedestrian": 3}
    still = ScenarioConfig(world="courtyard", seed=7, scale=0.25, duration=1.0, map_leaf=0.2, movers=0)
    generate(still, tmp_path / "still", progress=False)
    assert filecmp.cmp(tiny / "a" / "global_map.pcd", tmp_path / "still" / "global_map.pcd", shallow=False)
    assert filecmp.cmp(tiny / "a" / "ground_truth.tum", tmp_path / "still" / "ground_truth.tum", shallow=False)
    with rosbag.Bag(str(tiny / "a" / "scenario.bag")) as moving:
        clouds = [m for _, m, _ in moving.read_messages(topics=["points"])]
    with rosbag.Bag(str(tmp_path / "still" / "scenario.bag")) as bag:
        static = [m for _, m, _ in bag.read_messages(topics=["points"])]
    assert len(clouds) == len(static)
    assert any(a.data != b.data for a, b in zip_equal(clouds, static))


def test_bag_has_the_right_topics_types_frames_and_stamps(tiny):
    d = tiny / "a"
    t0 = TINY.start_time
    with rosbag.Bag(str(d / "scenario.bag")) as bag:
        info = bag.get_type_and_topic_info().topics
        assert {k: v.msg_type for k, v in info.items()} == {
            "points": "sensor_msgs/PointCloud2",
            "imu": "sensor_msgs/Imu",
            "ground_truth": "nav_msgs/Odometry",
            "/tf_static": "tf2_msgs/TFMessage",
        }
        assert info["points"].message_count == 10
        assert info["imu"].message_count == 201
        assert info["ground_truth"].message_count == 101
        record, header = {}, {}
        for topic, msg, t in bag.read_messages():
            record.setdefault(topic, []).append(t.to_sec())
            stamp = msg.transforms[0].header.stamp if topic == "/tf_static" else msg.header.stamp
            header.setdefault(topic, []).append(stamp.to_sec())
            if topic == "points":
                assert msg.header.frame_id == "lidar"
                assert [f.name for f in msg.fields] == ["x", "y", "z", "intensity", "ring", "time"]
                assert msg.point_step == POINT_DTYPE.itemsize and len(msg.data) == msg.width * msg.point_step
                pts = np.frombuffer(msg.data, POINT_DTYPE)
                assert pts["time"].min() >= 0.0 and pts["time"].max() < 0.1
                assert len(pts) > 5000
                assert t.to_sec() == pytest.approx(msg.header.stamp.to_sec() + 0.1, abs=1e-6)
            elif topic == "imu":
                assert msg.header.frame_id == "base_link"
            elif topic == "ground_truth":
                assert (msg.header.frame_id, msg.child_frame_id) == ("map", "base_link")
            else:
                tf = msg.transforms[0]
                assert (tf.header.frame_id, tf.child_frame_id) == ("base_link", "lidar")
                tr = tf.transform.translation
                assert (tr.x, tr.y, tr.z) == pytest.approx(MOUNTS["courtyard"])
        all_records = [t for _, _, t in bag.read_messages()]
    assert all(a <= b for a, b in pairwise(all_records))
    for topic, stamps in header.items():
        assert np.all(np.diff(stamps) > 0), topic
        assert stamps[0] >= t0 - 1e-6 and stamps[-1] <= t0 + TINY.duration + 1e-6
    assert header["points"][0] == pytest.approx(t0)


def test_ground_truth_topic_matches_tum_and_yaml_records_parameters(tiny):
    d = tiny / "a"
    tum = np.loadtxt(d / "ground_truth.tum")
    with rosbag.Bag(str(d / "scenario.bag")) as bag:
        odom = [m for _, m, _ in bag.read_messages(topics=["ground_truth"])]
    assert len(odom) == len(tum)
    for row, m in zip_equal(tum[::25], odom[::25]):
        p, q = m.pose.pose.position, m.pose.pose.orientation
        np.testing.assert_allclose([m.header.stamp.to_sec(), p.x, p.y, p.z], row[:4], atol=2e-6)
        np.testing.assert_allclose([q.x, q.y, q.z, q.w], row[4:], atol=2e-9)
    meta = yaml.safe_load((d / "scenario.yaml").read_text())
    assert meta["parameters"]["seed"] == 7 and meta["parameters"]["sensor"] == "livox"
    assert meta["localization_run"]["duration_s"] == pytest.approx(1.0)


def _point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance of points p (k, 3) to triangles (a, b, c) (m, 3): (k, m). Closest-point regions after
    Ericson, Real-Time Collision Detection, 5.1.5."""
    p = p[:, None, :]
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c
    d1, d2 = np.sum(ab * ap, -1), np.sum(ac * ap, -1)
    d3, d4 = np.sum(ab * bp, -1), np.sum(ac * bp, -1)
    d5, d6 = np.sum(ab * cp, -1), np.sum(ac * cp, -1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = a + (d1 / (d1 - d3))[..., None] * ab
        on_ac = a + (d2 / (d2 - d6))[..., None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[..., None] * (c - b)
        denom = 1.0 / (va + vb + vc)
        inside = a + (vb * denom)[..., None] * ab + (vc * denom)[..., None] * ac
    conds = [
        (d1 <= 0) & (d2 <= 0),
        (d3 >= 0) & (d4 <= d3),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (d6 >= 0) & (d5 <= d6),
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),
    ]
    shape = (*conds[0].shape, 3)
    choices = [np.broadcast_to(x, shape) for x in (a, b, on_ab, c, on_ac, on_bc)]
    closest = np.select([np.repeat(cnd[..., None], 3, -1) for cnd in conds], choices, inside)
    return np.linalg.norm(p - closest, axis=-1)


def test_point_triangle_distance_closed_forms():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    p = np.array([[0.2, 0.2, 0.5], [-1.0, -1.0, 0.0], [0.5, -2.0, 0.0], [1.0, 1.0, 0.0]])
    expected = [0.5, np.sqrt(2.0), 2.0, np.sqrt(0.5)]
    np.testing.assert_allclose(_point_triangle_distance(p, a, b, c)[:, 0], expected)


def test_prior_map_error_is_within_the_drift_bounds(tmp_path):
    cfg = TINY.resolved()
    world = worlds.make_world(cfg.world, cfg.seed, cfg.scale)
    loc = localization_trajectory(world, cfg.scale, scenario._rng(cfg.seed, 1)).truncated(cfg.duration)
    mapping = mapping_trajectory(world, loc, scenario._rng(cfg.seed, 2)).truncated(6.0)
    bounds = DriftBounds()
    est = drifted(mapping, bounds, scenario._rng(cfg.seed, 3))
    err = est.position - mapping.position
    assert np.hypot(err[:, 0], err[:, 1]).max() <= bounds.horizontal + 1e-9
    assert np.abs(err[:, 2]).max() <= bounds.vertical + 1e-9
    assert np.hypot(err[:, 0], err[:, 1]).max() > 0.5 * bounds.horizontal  # the drift is real
    leaf = 0.05
    cfg = ScenarioConfig(cfg.world, cfg.sensor, cfg.seed, cfg.scale, cfg.duration, leaf).resolved()
    mount = Mount(np.array(MOUNTS[cfg.world]), np.eye(3))
    sensor = get_sensor(cfg.sensor)
    with RayCaster(world.mesh) as caster:
        sim = SweepSimulator(world.mesh, caster, sensor, mount)
        scenario._write_map(tmp_path / "map.pcd", cfg, sim, mapping, mount, False)
    pts = read_pcd(tmp_path / "map.pcd").points
    sample = pts[np.random.default_rng(0).choice(len(pts), 1500, replace=False)]
    xyz = np.stack([sample["x"], sample["y"], sample["z"]], axis=1).astype(np.float64)
    tri = world.mesh.triangles.astype(np.float64)
    dist = np.min(
        np.concatenate(
            [
                _point_triangle_distance(xyz[i : i + 100], tri[:, 0], tri[:, 1], tri[:, 2])
                for i in range(0, len(xyz), 100)
            ]
        ),
        axis=1,
    )
    bound = bounds.point_bound(sensor.max_range) + 4 * sensor.range_sigma + leaf * np.sqrt(3) / 2
    assert dist.max() <= bound
    assert np.median(dist) <= bounds.horizontal + bounds.vertical  # typical points: the pose error alone


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["simulate", "moon"], "unknown scenario 'moon'"),
        (["simulate", "courtyard", "--sensor", "velodyne"], "unknown sensor 'velodyne'"),
        (["simulate", "courtyard", "--duration", "-5"], "--duration must be at least"),
        (["simulate", "urban", "--scale", "3"], "--scale must be between"),
        (["simulate", "urban", "--map-density", "0"], "--map-density"),
    ],
)
def test_bad_parameters_are_clear_errors(argv, needle, tmp_path, capsys):
    assert cli.main([*argv, "-o", str(tmp_path / "out"), "--quiet"]) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_existing_output_is_refused_and_interrupt_leaves_nothing(tmp_path, monkeypatch):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "old.txt").write_text("old")
    with pytest.raises(UserError, match="not empty; choose another one or pass --force"):
        generate(TINY, tmp_path / "taken", progress=False)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scenario, "_write_map", interrupted)
    with pytest.raises(KeyboardInterrupt):
        generate(TINY, tmp_path / "out", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    assert [p.name for p in (tmp_path / "taken").iterdir()] == ["old.txt"]
