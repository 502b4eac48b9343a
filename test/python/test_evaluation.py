"""Evaluation maths against closed forms, brute force and scipy; TUM files; resource protocols."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.association import associate
from grid_puzzle_localization.evaluation.metrics import (
    interpolated_errors,
    paired_errors,
    position_rmse,
    rotation_angle_deg,
)
from grid_puzzle_localization.evaluation.resources import (
    compare_to_baseline,
    map_memory,
    map_memory_ratios,
    mode_resources,
    protocol_processes,
    reduction,
)
from grid_puzzle_localization.evaluation.trajectory import Trajectory, make_trajectory, read_tum, write_tum
from grid_puzzle_localization.monitor.log import METRICS, MonitorLog
from grid_puzzle_localization.util.iteration import zip_equal

RNG = np.random.default_rng(7)


def straight(t: np.ndarray, v: float = 2.0, offset=(0.0, 0.0, 0.0)) -> Trajectory:
    """Driving along +x at ``v`` m/s, yaw 0."""
    xyz = np.stack([v * t, np.zeros_like(t), np.zeros_like(t)], axis=1) + np.asarray(offset)
    return make_trajectory(t, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1)))


def random_trajectory(n: int) -> Trajectory:
    t = 1.7e9 + np.cumsum(RNG.uniform(0.05, 0.15, n))
    return make_trajectory(t, RNG.normal(0, 100, (n, 3)), Rotation.random(n, random_state=3).as_quat())


def test_tum_round_trip(tmp_path):
    traj = random_trajectory(500)
    write_tum(tmp_path / "a.tum", traj)
    back = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(back.t, traj.t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.xyz, traj.xyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.quat, traj.quat, rtol=0, atol=1e-9)
    assert [p.name for p in tmp_path.iterdir()] == ["a.tum"]  # no temporary left behind


def test_tum_reads_comments_and_blank_lines(tmp_path):
    (tmp_path / "c.tum").write_text("# header\n\n1.0 1 2 3 0 0 0 1\n  # note\n2.5 4 5 6 0 0 1 0\n")
    traj = read_tum(tmp_path / "c.tum")
    np.testing.assert_array_equal(traj.t, [1.0, 2.5])
    np.testing.assert_array_equal(traj.xyz, [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1.0 1 2 3 0 0 0\n", "8 numbers"),
        ("1.0 1 2 3 0 0 0 x\n", "not a number"),
        ("2.0 1 2 3 0 0 0 1\n1.0 1 2 3 0 0 0 1\n", "increase strictly"),
        ("1.0 1 2 3 0 0 0 2\n", "unit quaternion"),
        ("1.0 nan 2 3 0 0 0 1\n", "NaN"),
    ],
)
def test_tum_bad_input_names_the_file(tmp_path, text, message):
    path = tmp_path / "bad.tum"
    path.write_text(text)
    with pytest.raises(UserError, match=message) as err:
        read_tum(path)
    assert str(path) in str(err.value)


def test_tum_missing_file():
    with pytest.raises(UserError, match=r"cannot read trajectory /nonexistent\.tum"):
        read_tum("/nonexistent.tum")


def test_association_against_brute_force():
    t_a = np.cumsum(RNG.uniform(0.01, 0.2, 400))
    t_b = np.cumsum(RNG.uniform(0.05, 0.5, 150))
    max_diff = 0.04
    ia, ib = associate(t_a, t_b, max_diff)
    expected = []
    for i, t in enumerate(t_a):
        j = int(np.argmin(np.abs(t_b - t)))
        if abs(t_b[j] - t) <= max_diff:
            expected.append((i, j))
    assert list(zip_equal(ia.tolist(), ib.tolist())) == expected
    assert len(expected) > 20


def test_association_with_time_shift_and_offset():
    t = np.arange(100) * 0.1
    ia, ib = associate(t, t + 0.03, max_diff=0.05)
    np.testing.assert_array_equal(ia, np.arange(100))
    np.testing.assert_array_equal(ib, np.arange(100))
    assert associate(t, t + 0.03, max_diff=0.02)[0].size == 0
    assert associate(t, t + 0.03, max_diff=1e-9, offset_b=-0.03)[0].size == 100  # the offset undoes the shift
    assert associate(t, np.array([4.02]), max_diff=0.05)[1].tolist() == [0]


def test_rmse_of_constant_offset_is_its_length():
    t = np.arange(200) * 0.1
    d = (0.03, -0.04, 0.012)
    assert position_rmse(straight(t), straight(t, offset=d), 0.01) == pytest.approx(np.linalg.norm(d), abs=1e-12)


def test_rmse_with_a_time_shift_along_the_motion():
    # b is stamped 10 ms late: pose i of b is where the vehicle was at t_i + 0.01, so each pair
    # differs by v * 0.01 along x, plus the offset.
    t = np.arange(300) * 0.1
    v, shift, d = 2.0, 0.01, np.array([0.03, -0.04, 0.0])
    b = straight(t + shift, v=v, offset=d)
    expected = np.linalg.norm(d + np.array([v * shift, 0, 0]))
    assert position_rmse(straight(t, v=v), b, max_diff=0.02) == pytest.approx(expected, abs=1e-12)


def test_rmse_of_a_sinusoidal_error_is_amplitude_over_root_two():
    period, per_period, amplitude = 4.0, 40, 0.05
    t = np.arange(5 * per_period) * (period / per_period)
    a = straight(t)
    lateral = a.xyz + np.stack([0 * t, amplitude * np.sin(2 * np.pi * t / period), 0 * t], axis=1)
    b = make_trajectory(t, lateral, a.quat)
    errors = paired_errors(a, b, 1e-6)
    assert errors.translation.rmse == pytest.approx(amplitude / np.sqrt(2), abs=1e-12)
    assert errors.translation.max == pytest.approx(amplitude, abs=1e-12)
    assert errors.translation.pairs == len(t)


def test_rotation_error_matches_scipy():
    q1 = Rotation.random(300, random_state=1)
    q2 = Rotation.random(300, random_state=2)
    expected = np.degrees((q1.inv() * q2).magnitude())
    np.testing.assert_allclose(rotation_angle_deg(q1.as_quat(), q2.as_quat()), expected, atol=1e-9)


def test_ape_with_known_yaw_and_position_error():
    t = np.arange(50) * 0.1
    gt = straight(t)
    yaw = np.radians(2.0)
    est = make_trajectory(t, gt.xyz + np.array([0, 0, 0.1]), np.tile(Rotation.from_euler("z", yaw).as_quat(), (50, 1)))
    errors = paired_errors(gt, est, 0.01)
    assert errors.translation.rmse == pytest.approx(0.1, abs=1e-12)
    assert errors.rotation.median == pytest.approx(2.0, abs=1e-9)
    assert errors.rotation.max == pytest.approx(2.0, abs=1e-9)


def test_no_common_time_is_a_clear_error():
    t = np.arange(10) * 0.1
    with pytest.raises(UserError, match="same clock"):
        position_rmse(straight(t), straight(t + 100.0), 0.05)


def fake_log(columns: dict[str, dict[str, list[float]]]) -> MonitorLog:
    """A monitor log with given cpu_percent and rss_bytes per process (others equal rss)."""
    names = list(columns)
    n = len(next(iter(columns.values()))["cpu_percent"])
    values = {m: {} for m in METRICS}
    for name, cols in columns.items():
        values["cpu_percent"][name] = np.array(cols["cpu_percent"], dtype=float)
        for m in ("rss_bytes", "uss_bytes", "pss_bytes"):
            values[m][name] = np.array(cols["rss_bytes"], dtype=float)
    pid = {name: np.where(np.isnan(values["rss_bytes"][name]), -1, 100 + k) for k, name in enumerate(names)}
    return MonitorLog(names, np.arange(n, dtype=float), np.arange(n, dtype=float), pid, values)


def test_protocols_and_reductions():
    roles_g = {"localizer": "/loc", "map_provider": "/prov"}
    global_log = fake_log(
        {
            "/loc": {"cpu_percent": [80, 100], "rss_bytes": [300e6, 300e6]},
            "/mgr": {"cpu_percent": [5, 5], "rss_bytes": [20e6, 20e6]},
        }
    )
    grid_log = fake_log(
        {
            "/loc": {"cpu_percent": [50, 70], "rss_bytes": [100e6, 120e6]},
            "/prov": {"cpu_percent": [10, np.nan], "rss_bytes": [50e6, np.nan]},  # provider gone at sample 2
            "/mgr": {"cpu_percent": [5, 5], "rss_bytes": [20e6, 20e6]},
        }
    )
    assert protocol_processes("global", roles_g, global_log, "paper") == ["/loc"]
    assert protocol_processes("grid_puzzle", roles_g, grid_log, "paper") == ["/loc", "/prov"]
    res = {
        "global": mode_resources("global", roles_g, global_log),
        "grid_puzzle": mode_resources("grid_puzzle", roles_g, grid_log),
    }
    assert res["global"]["paper"]["cpu_percent"]["mean"] == 90.0
    assert res["global"]["total"]["cpu_percent"]["mean"] == 95.0
    assert res["grid_puzzle"]["paper"]["cpu_percent"]["mean"] == (60 + 70) / 2
    assert res["grid_puzzle"]["total"]["rss_bytes"]["max"] == 170e6
    cmp = compare_to_baseline(res)["grid_puzzle"]
    assert cmp["paper"]["cpu_percent"]["mean"]["absolute"] == pytest.approx(65 - 90)
    assert cmp["paper"]["cpu_percent"]["mean"]["relative_percent"] == pytest.approx(100 * (65 - 90) / 90)
    assert cmp["paper"]["rss_bytes"]["mean"]["relative_percent"] == pytest.approx(100 * (135e6 - 300e6) / 300e6)
    assert reduction(0.0, 1.0)["relative_percent"] is None
    with pytest.raises(UserError, match="map_provider"):
        protocol_processes("grid_puzzle", {"localizer": "/loc"}, grid_log, "paper")


def test_the_provider_nodelet_is_not_counted_twice():
    """grid_puzzle: the provider nodelet lives in the localizer's manager, so both roles name that process and the
    paper protocol counts it once; grid_puzzle_rospy (the paper's setup) sums the manager and the provider."""
    log = fake_log(
        {
            "/mgr": {"cpu_percent": [50, 70], "rss_bytes": [100e6, 120e6]},
            "/loader": {"cpu_percent": [1, 1], "rss_bytes": [8e6, 8e6]},
            "/prov": {"cpu_percent": [10, 20], "rss_bytes": [50e6, 52e6]},
        }
    )
    nodelet = {"localizer": "/mgr", "map_provider": "/mgr"}
    rospy = {"localizer": "/mgr", "map_provider": "/prov"}
    assert protocol_processes("grid_puzzle", nodelet, log, "paper") == ["/mgr"]
    assert protocol_processes("grid_puzzle_rospy", rospy, log, "paper") == ["/mgr", "/prov"]
    assert protocol_processes("grid_puzzle", nodelet, log, "total") == ["/mgr", "/loader", "/prov"]
    paper = mode_resources("grid_puzzle", nodelet, log)["paper"]
    assert (paper["cpu_percent"]["mean"], paper["rss_bytes"]["mean"]) == (60.0, 110e6)
    paper = mode_resources("grid_puzzle_rospy", rospy, log)["paper"]
    assert (paper["cpu_percent"]["mean"], paper["rss_bytes"]["mean"]) == (75.0, 161e6)
    empty = fake_log(
        {"/mgr": {"cpu_percent": [1], "rss_bytes": [30e6]}, "/prov": {"cpu_percent": [1], "rss_bytes": [40e6]}}
    )
    assert map_memory("grid_puzzle", nodelet, log, empty)["paper"]["map_bytes"] == pytest.approx(110e6 - 30e6)
    assert map_memory("grid_puzzle_rospy", rospy, log, empty)["paper"]["map_bytes"] == pytest.approx(80e6 + 11e6)


def test_map_memory_is_rss_over_the_empty_map_run():
    roles_g = {"localizer": "/loc", "map_provider": "/prov"}
    full = {
        "global": fake_log({"/loc": {"cpu_percent": [1, 1], "rss_bytes": [300e6, 340e6]}}),
        "grid_puzzle": fake_log(
            {
                "/loc": {"cpu_percent": [1, 1], "rss_bytes": [60e6, 70e6]},
                "/prov": {"cpu_percent": [1, 1], "rss_bytes": [52e6, 52e6]},
            }
        ),
    }
    empty = {
        "global": fake_log({"/loc": {"cpu_percent": [1, 1, 1], "rss_bytes": [20e6, 20e6, 20e6]}}),
        "grid_puzzle": fake_log(
            {
                "/loc": {"cpu_percent": [1], "rss_bytes": [25e6]},
                "/prov": {"cpu_percent": [1], "rss_bytes": [50e6]},
            }
        ),
    }
    memory = {mode: map_memory(mode, roles_g, full[mode], empty[mode]) for mode in full}
    assert memory["global"]["paper"]["map_bytes"] == pytest.approx(320e6 - 20e6)
    loc = memory["grid_puzzle"]["processes"]["/loc"]
    assert (loc["rss_bytes_mean"], loc["empty_map_rss_bytes_mean"], loc["map_bytes"]) == (65e6, 25e6, 40e6)
    assert memory["grid_puzzle"]["paper"]["map_bytes"] == pytest.approx(40e6 + 2e6)
    assert memory["grid_puzzle"]["paper"]["processes"] == ["/loc", "/prov"]
    ratios = map_memory_ratios(memory)
    assert ratios["grid_puzzle"]["paper"] == pytest.approx(42e6 / 300e6) and "global" not in ratios
    # A process the empty-map run did not see has no map memory, nor has a protocol that counts it.
    partial = map_memory("grid_puzzle", roles_g, full["grid_puzzle"], empty["global"])
    assert partial["processes"]["/prov"]["map_bytes"] is None and partial["paper"]["map_bytes"] is None
    assert map_memory_ratios({"global": memory["global"], "grid_puzzle": partial})["grid_puzzle"]["paper"] is None


def test_paper_figures_reproduce_with_reduction():
    # The paper's courtyard memory: 166.01 MB -> 111.02 MB is a 33.12 % reduction.
    assert reduction(166.01, 111.02)["relative_percent"] == pytest.approx(-33.12, abs=0.01)
    assert reduction(74.79, 56.06)["absolute"] == pytest.approx(-18.73, abs=1e-9)


def test_cross_check_with_evo():
    evo_sync = pytest.importorskip(
        "evo.core.sync", reason="evo is not installed (not pinned: it replaces Debian's numpy in the venv)"
    )
    from evo.core import metrics as evo_metrics
    from evo.core.trajectory import PoseTrajectory3D

    def evo_traj(tr: Trajectory) -> PoseTrajectory3D:
        return PoseTrajectory3D(tr.xyz, tr.quat[:, [3, 0, 1, 2]], tr.t)  # evo: w first

    ref = random_trajectory(300)
    t_est = ref.t + RNG.uniform(-0.004, 0.004, len(ref))
    est = make_trajectory(
        t_est,
        ref.xyz + RNG.normal(0, 0.05, (len(ref), 3)),
        (Rotation.from_quat(ref.quat) * Rotation.from_rotvec(RNG.normal(0, 0.01, (len(ref), 3)))).as_quat(),
    )
    ours = paired_errors(ref, est, 0.01)
    r, e = evo_sync.associate_trajectories(evo_traj(ref), evo_traj(est), max_diff=0.01)
    for relation, stats in (
        (evo_metrics.PoseRelation.translation_part, ours.translation),
        (evo_metrics.PoseRelation.rotation_angle_deg, ours.rotation),
    ):
        ape = evo_metrics.APE(relation)
        ape.process_data((r, e))
        assert ape.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(stats.rmse, rel=1e-9)
        assert ape.get_statistic(evo_metrics.StatisticsType.max) == pytest.approx(stats.max, rel=1e-9)
        assert ape.get_statistic(evo_metrics.StatisticsType.median) == pytest.approx(stats.median, rel=1e-9)


def test_dense_reference_pairs_each_sparse_pose_once():
    # Ground truth at 100 Hz, estimate at 10 Hz on the same clock: 10 Hz pairs (evo's rule: iterate
    # over the shorter trajectory), errors exactly the 2 cm offset.
    t_gt = 100.0 + np.arange(1000) * 0.01
    t_est = t_gt[::10]
    errors = paired_errors(straight(t_gt), straight(t_est, offset=(0.0, 0.02, 0.0)), 0.005)
    assert errors.translation.pairs == len(t_est)
    assert errors.translation.max == pytest.approx(0.02, abs=1e-12)
    np.testing.assert_array_equal(errors.t, t_est)


def test_interpolated_reference_removes_the_stamp_offset():
    # Estimate stamped 3 ms off the 100 Hz ground-truth grid while driving 5 m/s: nearest pairing
    # sees 1.5 cm of error that is only timing; interpolation sees none. Yaw turns at 0.3 rad/s: slerp
    # recovers the orientation at the estimate's time exactly.
    t_gt = 100.0 + np.arange(1000) * 0.01
    t_est = t_gt[5:-5:10] + 0.003

    def turning(t):
        yaw = 0.3 * (t - 100.0)
        xyz = np.stack([5.0 * (t - 100.0), 0 * t, 0 * t], axis=1)
        return make_trajectory(t, xyz, Rotation.from_euler("z", yaw).as_quat())

    gt, est = turning(t_gt), turning(t_est)
    assert paired_errors(gt, est, 0.005).translation.max == pytest.approx(5.0 * 0.003, abs=1e-9)
    exact = interpolated_errors(gt, est, 0.005)
    assert exact.translation.pairs == len(t_est)
    assert exact.translation.max < 1e-9 and exact.rotation.max < 1e-6
    # Poses beyond the reference's span are skipped, not extrapolated.
    late = turning(np.array([t_gt[-1] + 0.002]))
    with pytest.raises(UserError, match="same clock"):
        interpolated_errors(gt, late, 0.005)


def test_tum_nanosecond_stamps_are_written_digit_for_digit(tmp_path):
    stamps_ns = 1_700_000_000_000_000_000 + np.array([0, 5_000_001, 10_000_002, 999_999_999])
    traj = make_trajectory(stamps_ns * 1e-9, RNG.normal(0, 100, (4, 3)), Rotation.random(4, random_state=4).as_quat())
    write_tum(tmp_path / "ns.tum", traj, stamps_ns)
    lines = (tmp_path / "ns.tum").read_text().splitlines()[1:]
    assert [line.split()[0] for line in lines] == [
        "1700000000.000000000",
        "1700000000.005000001",
        "1700000000.010000002",
        "1700000000.999999999",
    ]
    back = read_tum(tmp_path / "ns.tum")
    np.testing.assert_allclose(back.xyz, traj.xyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.quat, traj.quat, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="nanoseconds"):
        write_tum(tmp_path / "bad.tum", traj, stamps_ns + 10**6)
