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
from grid_puzzle_localization.evaluation.trajectory import make_trajectory, write_tum
from grid_puzzle_localization.monitor.log import METRICS, MonitorLog, write_csv
from grid_puzzle_localization.report.build import RunInfo, build_report, write_run_info

MIB = 1024 * 1024


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
    t = 100.0 + np.arange(300) * 0.1
    gt = circle(t)
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "global" / "trajectory.tum", circle(t + 0.002, offset=(0.01, 0.0, 0.0)))
    write_tum(tmp_path / "grid_puzzle" / "trajectory.tum", circle(t + 0.002, offset=(0.01, 0.03, 0.0)))
    write_csv(
        tmp_path / "global" / "monitor.csv",
        synthetic_log({"/ndt_localizer": 80.0, "/manager": 4.0}, {"/ndt_localizer": 300.0, "/manager": 20.0}),
    )
    write_csv(
        tmp_path / "grid_puzzle" / "monitor.csv",
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
            {"/ndt_localizer": 1.0, "/provider": 1.0, "/manager": 1.0},
            {"/ndt_localizer": 25.0, "/provider": 50.0, "/manager": 20.0},
            n=8,
        ),
    )
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
    roles = {"localizer": "/ndt_localizer", "map_provider": "/provider"}
    write_run_info(
        tmp_path,
        RunInfo(
            scenario={"name": "synthetic", "n": 3, "k": 2, "grid_size_m": 2.0},
            modes=["global", "grid_puzzle"],
            roles={"global": {"localizer": "/ndt_localizer"}, "grid_puzzle": roles},
            ground_truth=str(tmp_path / "gt.tum"),
            storage=storage,
            max_diff_s=0.01,
        ),
    )
    return tmp_path


def test_report_figures_match_closed_form(experiment):
    summary = build_report(experiment)
    on_disk = json.loads((experiment / "summary.json").read_text())
    assert on_disk["modes"]["grid_puzzle"]["poses"] == summary["modes"]["grid_puzzle"]["poses"] == 300
    # grid puzzle = global + 3 cm in y, at the same stamps: the paper's RMSE is exactly 0.03 m.
    between = on_disk["between_modes"]["grid_puzzle_vs_global"]
    assert between["translation_m"]["rmse"] == pytest.approx(0.03, abs=1e-9)
    assert between["rotation_deg"]["max"] == pytest.approx(0.0, abs=1e-6)
    # Against ground truth interpolated at the estimate's (2 ms late) stamps: the 1 cm offset, up to
    # the chord error of linear interpolation on the 20 m circle (0.2 m steps: 0.25 mm). The last pose
    # lies after the ground truth ends and is not extrapolated.
    ape = on_disk["modes"]["global"]["ape"]["translation_m"]
    assert ape["rmse"] == pytest.approx(0.01, abs=3e-4) and ape["pairs"] == 299
    g, p = on_disk["modes"]["global"]["resources"], on_disk["modes"]["grid_puzzle"]["resources"]
    assert g["paper"]["processes"] == ["/ndt_localizer"]
    assert g["paper"]["cpu_percent"]["mean"] == 80.0
    assert g["total"]["cpu_percent"]["mean"] == 84.0
    assert p["paper"]["cpu_percent"]["mean"] == 60.0
    assert p["paper"]["rss_bytes"]["p95"] == 160.0 * MIB
    red = on_disk["reductions"]["grid_puzzle"]["paper"]
    assert red["cpu_percent"]["mean"]["absolute"] == pytest.approx(-20.0)
    assert red["rss_bytes"]["mean"]["relative_percent"] == pytest.approx(100 * (160 - 300) / 300)
    assert on_disk["paper"]["urban"]["tile_files"] == 47480
    # Map memory: mean RSS minus the empty-map run's, per process and summed per protocol.
    assert on_disk["modes"]["global"]["map_memory"]["paper"]["map_bytes"] == (300 - 20) * MIB
    assert on_disk["modes"]["global"]["map_memory"]["total"]["map_bytes"] == (300 - 20 + 20 - 19) * MIB
    assert on_disk["modes"]["grid_puzzle"]["map_memory"]["paper"]["map_bytes"] == (100 - 25 + 60 - 50) * MIB
    assert on_disk["map_memory_ratios"]["grid_puzzle"]["paper"] == pytest.approx(85 / 280)


def test_report_markdown_and_plots_parse(experiment):
    build_report(experiment)
    report = (experiment / "report.md").read_text()
    table = [line for line in report.splitlines() if line.startswith("| CPU, grid puzzle")]
    assert table == ["| CPU, grid puzzle [% of one core] | 60.0 | 56.1 | 237.9 |"]
    assert "| CPU change | -20.0 pts (-25.0 %) | -18.7 pts (-25.0 %) | -15.4 pts (-6.1 %) |" in report
    assert "| Memory change | -140.0 MiB (-46.7 %) | -55.0 MB (-33.1 %) | -316.3 MB (-62.1 %) |" in report
    assert "| Trajectory RMSE, grid puzzle vs global [m] | 0.0300 | 0.0433 | 0.0677 |" in report
    assert "| Tile files | 250 | 8,282 | 47,480 |" in report
    assert "| grid puzzle | /provider | 60.0 | 50.0 | 10.0 | |" in report
    assert "| grid puzzle | paper protocol | | | 85.0 | 0.30 x |" in report
    assert "| global map | paper protocol | | | 280.0 | 1.00 x |" in report
    assert "| grid puzzle tiles | 250 | 1,075,000 | 1,000,000 | 75,000 | 25,000 | – | – |" in report
    for name in ("cpu", "memory", "trajectories", "errors"):
        assert f"(plots/{name}.png)" in report
        image = imread(experiment / "plots" / f"{name}.png")
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
        assert np.ptp(image[..., :3]) > 0.5  # something was drawn
    leftovers = [p.name for p in experiment.rglob("*.tmp")]
    assert leftovers == []


def test_gpm_report_prints_the_table(experiment, capsys):
    assert main(["report", str(experiment)]) == 0
    assert "| Trajectory RMSE, grid puzzle vs global [m] | 0.0300 |" in capsys.readouterr().out


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
