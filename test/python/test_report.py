"""The report builds from synthetic experiment outputs whose figures are known in closed form, and
every file it writes parses."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest
from matplotlib.image import imread

from grid_puzzle_localization.cli import main
from grid_puzzle_localization.evaluation.resources import mode_resources
from grid_puzzle_localization.evaluation.trajectory import make_trajectory, write_tum
from grid_puzzle_localization.monitor.log import METRICS, MonitorLog, read_csv, write_csv
from grid_puzzle_localization.pcd.writer import write_pcd
from grid_puzzle_localization.report.build import RunInfo, build_report, write_run_info
from grid_puzzle_localization.report.map_view import map_top_view
from grid_puzzle_localization.report.plots import trajectory_figure

MIB = 1024 * 1024
# A 60 m x 40 m map around the 20 m circle, 2,400 points on a 1 m grid.
MAP_X, MAP_Y = np.meshgrid(np.arange(-30.0, 30.0), np.arange(-20.0, 20.0))
MAP_POINTS = np.zeros(MAP_X.size, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
MAP_POINTS["x"], MAP_POINTS["y"] = MAP_X.ravel(), MAP_Y.ravel()


def circle(t: np.ndarray, offset=(0.0, 0.0, 0.0)):
    yaw = 0.1 * t
    xyz = np.stack([20 * np.cos(yaw), 20 * np.sin(yaw), 0 * t], axis=1) + np.asarray(offset)
    quat = np.stack([0 * t, 0 * t, np.sin((yaw + np.pi / 2) / 2), np.cos((yaw + np.pi / 2) / 2)], axis=1)
    return make_trajectory(t, xyz, quat)


def synthetic_log(cpu: dict[str, float], rss_mib: dict[str, float], n: int = 20) -> MonitorLog:
    names = list(cpu)
    values = {m: {} for m in METRICS}
    for name in names:
        values["cpu_percent"][name] = np.full(n, cpu[name])
        for m in ("rss_bytes", "uss_bytes", "pss_bytes"):
            values[m][name] = np.full(n, rss_mib[name] * MIB)
    pid = {name: np.full(n, 1000 + k) for k, name in enumerate(names)}
    t = np.arange(n) * 0.5
    return MonitorLog(names, t, 1.7e9 + t, pid, values)


@pytest.fixture
def experiment(tmp_path):
    """global, grid_puzzle (the provider nodelet in the localizer's process /ndt_localizer; /provider_loader is
    its loader) and grid_puzzle_rospy (the provider's own process /provider); /manager is a helper process."""
    t = 100.0 + np.arange(300) * 0.1
    gt = circle(t)
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "global" / "trajectory.tum", circle(t + 0.002, offset=(0.01, 0.0, 0.0)))
    write_tum(tmp_path / "grid_puzzle" / "trajectory.tum", circle(t + 0.002, offset=(0.01, -0.02, 0.0)))
    write_tum(tmp_path / "grid_puzzle_rospy" / "trajectory.tum", circle(t + 0.002, offset=(0.01, 0.03, 0.0)))
    write_csv(
        tmp_path / "global" / "monitor.csv",
        synthetic_log({"/ndt_localizer": 80.0, "/manager": 4.0}, {"/ndt_localizer": 300.0, "/manager": 20.0}),
    )
    write_csv(
        tmp_path / "grid_puzzle" / "monitor.csv",
        synthetic_log(
            {"/ndt_localizer": 64.0, "/manager": 4.0, "/provider_loader": 1.0},
            {"/ndt_localizer": 135.0, "/manager": 20.0, "/provider_loader": 8.0},
        ),
    )
    write_csv(
        tmp_path / "grid_puzzle_rospy" / "monitor.csv",
        synthetic_log(
            {"/ndt_localizer": 50.0, "/provider": 10.0, "/manager": 4.0},
            {"/ndt_localizer": 100.0, "/provider": 60.0, "/manager": 20.0},
        ),
    )
    # The same launches against an empty map (the floors the map memory subtracts).
    write_csv(
        tmp_path / "global" / "empty_map" / "monitor.csv",
        synthetic_log({"/ndt_localizer": 1.0, "/manager": 1.0}, {"/ndt_localizer": 20.0, "/manager": 19.0}, n=8),
    )
    write_csv(
        tmp_path / "grid_puzzle" / "empty_map" / "monitor.csv",
        synthetic_log(
            {"/ndt_localizer": 1.0, "/manager": 1.0, "/provider_loader": 1.0},
            {"/ndt_localizer": 26.0, "/manager": 20.0, "/provider_loader": 8.0},
            n=8,
        ),
    )
    write_csv(
        tmp_path / "grid_puzzle_rospy" / "empty_map" / "monitor.csv",
        synthetic_log(
            {"/ndt_localizer": 1.0, "/provider": 1.0, "/manager": 1.0},
            {"/ndt_localizer": 25.0, "/provider": 50.0, "/manager": 20.0},
            n=8,
        ),
    )
    write_pcd(tmp_path / "map.pcd", MAP_POINTS)
    storage = {
        "global_map": {
            "files": 1,
            "bytes": 1_000_300,
            "data_bytes": 1_000_000,
            "header_bytes": 300,
            "disk_bytes": 1_003_520,
        },
        "tiles": {
            "files": 250,
            "bytes": 1_075_000,
            "data_bytes": 1_000_000,
            "header_bytes": 75_000,
            "disk_bytes": 1_100_000,
            "data_overhead_bytes": 0,
        },
    }
    roles = {
        "global": {"localizer": "/ndt_localizer"},
        "grid_puzzle": {"localizer": "/ndt_localizer", "map_provider": "/ndt_localizer"},
        "grid_puzzle_rospy": {"localizer": "/ndt_localizer", "map_provider": "/provider"},
    }
    write_run_info(
        tmp_path,
        RunInfo(
            scenario={"name": "synthetic", "n": 3, "k": 2, "grid_size_m": 2.0},
            modes=["global", "grid_puzzle", "grid_puzzle_rospy"],
            roles=roles,
            ground_truth=str(tmp_path / "gt.tum"),
            global_map=str(tmp_path / "map.pcd"),
            storage=storage,
            max_diff_s=0.01,
        ),
    )
    return tmp_path


def test_report_figures_match_closed_form(experiment):
    summary = build_report(experiment)
    on_disk = json.loads((experiment / "summary.json").read_text())
    assert on_disk["modes"]["grid_puzzle"]["poses"] == summary["modes"]["grid_puzzle"]["poses"] == 300
    # Each grid puzzle run = the global run + 2 cm (nodelet) and 3 cm (rospy) in y, at the same stamps: the
    # paper's RMSE is exactly that offset.
    for mode, offset in (("grid_puzzle", 0.02), ("grid_puzzle_rospy", 0.03)):
        between = on_disk["between_modes"][f"{mode}_vs_global"]
        assert between["translation_m"]["rmse"] == pytest.approx(offset, abs=1e-9)
        assert between["rotation_deg"]["max"] == pytest.approx(0.0, abs=1e-6)
    # Against ground truth interpolated at the estimate's (2 ms late) stamps: the 1 cm offset, up to
    # the chord error of linear interpolation on the 20 m circle (0.2 m steps: 0.25 mm). The last pose
    # lies after the ground truth ends and is not extrapolated.
    ape = on_disk["modes"]["global"]["ape"]["translation_m"]
    assert ape["rmse"] == pytest.approx(0.01, abs=3e-4) and ape["pairs"] == 299
    g, n, r = (on_disk["modes"][m]["resources"] for m in ("global", "grid_puzzle", "grid_puzzle_rospy"))
    assert g["paper"]["processes"] == ["/ndt_localizer"]
    assert g["paper"]["cpu_percent"]["mean"] == 80.0
    assert g["total"]["cpu_percent"]["mean"] == 84.0
    # The provider nodelet lives in the localizer's process: the paper protocol counts that process once.
    assert n["paper"]["processes"] == ["/ndt_localizer"]
    assert (n["paper"]["cpu_percent"]["mean"], n["paper"]["rss_bytes"]["mean"]) == (64.0, 135.0 * MIB)
    assert n["total"]["rss_bytes"]["mean"] == (135 + 20 + 8) * MIB
    # The paper's setup sums the localizer's process and the rospy provider's.
    assert r["paper"]["processes"] == ["/ndt_localizer", "/provider"]
    assert r["paper"]["cpu_percent"]["mean"] == 60.0
    assert r["paper"]["rss_bytes"]["p95"] == 160.0 * MIB
    red = on_disk["reductions"]["grid_puzzle_rospy"]["paper"]
    assert red["cpu_percent"]["mean"]["absolute"] == pytest.approx(-20.0)
    assert red["rss_bytes"]["mean"]["relative_percent"] == pytest.approx(100 * (160 - 300) / 300)
    assert on_disk["reductions"]["grid_puzzle"]["paper"]["cpu_percent"]["mean"]["absolute"] == pytest.approx(-16.0)
    assert on_disk["paper"]["urban"]["tile_files"] == 47480
    # Map memory: mean RSS minus the empty-map run's, per process and summed per protocol.
    memory = {mode: on_disk["modes"][mode]["map_memory"] for mode in on_disk["modes"]}
    assert memory["global"]["paper"]["map_bytes"] == (300 - 20) * MIB
    assert memory["global"]["total"]["map_bytes"] == (300 - 20 + 20 - 19) * MIB
    assert memory["grid_puzzle"]["paper"]["map_bytes"] == (135 - 26) * MIB
    assert memory["grid_puzzle_rospy"]["paper"]["map_bytes"] == (100 - 25 + 60 - 50) * MIB
    assert on_disk["map_memory_ratios"]["grid_puzzle"]["paper"] == pytest.approx(109 / 280)
    assert on_disk["map_memory_ratios"]["grid_puzzle_rospy"]["paper"] == pytest.approx(85 / 280)


def test_one_run_per_mode_gives_that_runs_figures(experiment):
    # Without --repeats every resource figure is the one run's, as computed from its monitor log alone, and the spread
    # is that run: 60 % for the paper's setup, 0.75 of the global map's 80 %.
    summary = build_report(experiment)
    assert summary["repeats"]["count"] == 1
    for mode, m in summary["modes"].items():
        single = mode_resources(mode, m["roles"], read_csv(experiment / mode / "monitor.csv"))
        assert m["resources"] == single
        assert m["per_repeat"] == [{"repeat": 1, "resources": single, "events": []}]
    spread = summary["repeats"]["spread"]["grid_puzzle_rospy"]["paper"]["cpu_percent"]
    assert spread == {
        "means": [60.0],
        "min": 60.0,
        "max": 60.0,
        "vs_baseline": {"per_repeat": [0.75], "min": 0.75, "max": 0.75},
    }


def test_first_section_shows_both_grid_puzzle_modes_against_the_global_map(experiment):
    build_report(experiment)
    report = (experiment / "report.md").read_text()
    first = report.split("## Grid puzzle against the global map")[1].split("\n## ")[0]
    rospy = "grid puzzle, the paper's setup (rospy provider)"
    # CPU and RSS means with their ratios to the global map's: 64/80, 135/300; 60/80, 160/300; under the total
    # protocol (every process) 69/84, 163/320; 64/84, 180/320.
    for row in (
        "| paper | global map | /ndt_localizer | 80.0 | 1.00 x | 300.0 | 1.00 x |",
        "| paper | grid puzzle | /ndt_localizer | 64.0 | 0.80 x | 135.0 | 0.45 x |",
        f"| paper | {rospy} | /ndt_localizer, /provider | 60.0 | 0.75 x | 160.0 | 0.53 x |",
        "| total | global map | /ndt_localizer, /manager | 84.0 | 1.00 x | 320.0 | 1.00 x |",
        "| total | grid puzzle | /ndt_localizer, /manager, /provider_loader | 69.0 | 0.82 x | 163.0 | 0.51 x |",
        f"| total | {rospy} | /ndt_localizer, /provider, /manager | 64.0 | 0.76 x | 180.0 | 0.56 x |",
    ):
        assert row in first, row
    # Map memory split per process: the manager (with the nodelet, also the provider), the rospy provider; the
    # protocol sums and their ratios: 109/280, 109/281; 85/280, 85/281.
    for row in (
        "| global map | 280.0 | – | 280.0 | 1.00 x | 281.0 | 1.00 x |",
        "| grid puzzle | 109.0 | – | 109.0 | 0.39 x | 109.0 | 0.39 x |",
        f"| {rospy} | 75.0 | 10.0 | 85.0 | 0.30 x | 85.0 | 0.30 x |",
    ):
        assert row in first, row
    # What a user gets comes before the paper's setup.
    assert first.index("| paper | grid puzzle |") < first.index(f"| paper | {rospy} |")


def test_report_markdown_and_plots_parse(experiment):
    build_report(experiment)
    report = (experiment / "report.md").read_text()
    rospy = "grid puzzle, the paper's setup (rospy provider)"
    assert (
        f"| figure (means; paper protocol) | ours: grid puzzle | ours: {rospy} | paper courtyard | paper urban |"
        in (report)
    )
    assert "| CPU, global map [% of one core] | 80.0 | 80.0 | 74.8 | 253.3 |" in report
    assert "| CPU, grid puzzle [% of one core] | 64.0 | 60.0 | 56.1 | 237.9 |" in report
    assert "| CPU change | -16.0 pts (-20.0 %) | -20.0 pts (-25.0 %) | -18.7 pts (-25.0 %) | -15.4 pts (-6.1 %) |" in (
        report
    )
    assert (
        "| Memory change | -165.0 MiB (-55.0 %) | -140.0 MiB (-46.7 %) | -55.0 MB (-33.1 %) | -316.3 MB (-62.1 %) |"
        in (report)
    )
    assert "| Trajectory RMSE, grid puzzle vs global [m] | 0.0200 | 0.0300 | 0.0433 | 0.0677 |" in report
    assert "| Tile files | 250 | 250 | 8,282 | 47,480 |" in report
    assert f"| {rospy} | /provider | 60.0 | 50.0 | 10.0 | |" in report
    assert f"| {rospy} | paper protocol | | | 85.0 | 0.30 x |" in report
    assert "| global map | paper protocol | | | 280.0 | 1.00 x |" in report
    assert "| grid puzzle tiles | 250 | 1,075,000 | 1,000,000 | 75,000 | 25,000 | – | – |" in report
    for name in ("cpu", "memory", "trajectories", "errors"):
        assert f"(plots/{name}.png)" in report
        image = imread(experiment / "plots" / f"{name}.png")
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
        assert np.ptp(image[..., :3]) > 0.5  # something was drawn
    leftovers = [p.name for p in experiment.rglob("*.tmp")]
    assert leftovers == []


def test_map_top_view_is_every_kth_point_bounded(tmp_path):
    write_pcd(tmp_path / "map.pcd", MAP_POINTS)
    xy = map_top_view(tmp_path / "map.pcd", max_points=1000)  # 2,400 points: every 3rd, 800 of them
    np.testing.assert_array_equal(xy, np.stack([MAP_POINTS["x"], MAP_POINTS["y"]], axis=1)[::3])
    assert len(map_top_view(tmp_path / "map.pcd")) == len(MAP_POINTS)


def test_trajectories_are_drawn_over_the_map(experiment):
    xy = map_top_view(experiment / "map.pcd")
    traj = circle(100.0 + np.arange(300) * 0.1)
    ax = trajectory_figure({"grid_puzzle": traj}, traj, xy).axes[0]
    # One layer of points under the lines, holding the map's x and y, on equal axes that show all of it.
    (layer,) = ax.collections
    np.testing.assert_array_equal(layer.get_offsets(), xy)
    assert layer.get_zorder() < min(line.get_zorder() for line in ax.lines) and len(ax.lines) == 2
    assert ax.get_aspect() == 1.0
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 <= -30.0 and x1 >= 29.0 and y0 <= -20.0 and y1 >= 19.0
    assert len(trajectory_figure({"grid_puzzle": traj}, traj).axes[0].collections) == 0


def test_gpm_report_prints_the_tables(experiment, capsys):
    assert main(["report", str(experiment)]) == 0
    out = capsys.readouterr().out
    assert out.index("| paper | grid puzzle | /ndt_localizer | 64.0 | 0.80 x |") < out.index(
        "| Trajectory RMSE, grid puzzle vs global [m] | 0.0200 | 0.0300 |"
    )


def test_report_of_a_directory_without_run_json_is_a_user_error(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "run.json" in capsys.readouterr().err


def test_written_files_get_the_umask_mode(experiment):
    # Not the owner-only mode of the temporary file they were written to.
    umask = os.umask(0)
    os.umask(umask)
    build_report(experiment)
    for path in [experiment / "summary.json", experiment / "report.md", experiment / "plots" / "cpu.png"]:
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path
