"""`gpm experiment --repeats`: the modes run interleaved round by round, each run keeps its own monitor output, and
the report's CPU and memory figures are the medians over the runs with their spread, all checked against figures
computed here from synthetic monitor logs in closed form."""

from __future__ import annotations

import json

import numpy as np
import pytest

from grid_puzzle_localization.evaluation.repeats import median_of, median_resources, value_range
from grid_puzzle_localization.evaluation.resources import mode_resources
from grid_puzzle_localization.evaluation.trajectory import make_trajectory, write_tum
from grid_puzzle_localization.experiment import runner
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.modes import interleaved_runs
from grid_puzzle_localization.monitor.log import METRICS, MonitorLog, read_csv, write_csv
from grid_puzzle_localization.pcd.writer import write_pcd
from grid_puzzle_localization.report.build import RunInfo, build_report, run_dir, write_run_info

MIB = 1024 * 1024
SAMPLES = 21  # a ramp a + b i, i = 0..20: mean and median a + 10 b, p95 (linear interpolation) a + 19 b, max a + 20 b
MODES = ["global", "grid_puzzle"]
ROLES = {
    "global": {"localizer": "/ndt_localizer"},
    "grid_puzzle": {"localizer": "/ndt_localizer", "map_provider": "/ndt_localizer"},
}
HELPERS = {"global": {"/manager": 4.0}, "grid_puzzle": {"/manager": 4.0, "/provider_loader": 1.0}}
# Per mode and run: the localizer's CPU ramp (a [%], b [% per sample]) and its constant RSS [MiB]. The rounds differ
# (round 2 slow, round 3 fast) as a busy machine makes them; the medians come from different rounds.
LOCALIZER = {
    "global": [(9.0, 0.05, 300.0), (10.0, 0.02, 310.0), (8.5, 0.01, 305.0)],
    "grid_puzzle": [(9.0, 0.02, 135.0), (9.5, 0.03, 150.0), (8.0, 0.03, 140.0)],
}


def ramp_log(cpu: dict[str, tuple[float, float]], rss_mib: dict[str, float]) -> MonitorLog:
    """Each process's CPU a + b i over SAMPLES samples, its memory constant."""
    i = np.arange(SAMPLES, dtype=np.float64)
    values = {m: {} for m in METRICS}
    for name, (a, b) in cpu.items():
        values["cpu_percent"][name] = a + b * i
        for m in ("rss_bytes", "uss_bytes", "pss_bytes"):
            values[m][name] = np.full(SAMPLES, rss_mib[name] * MIB)
    pid = {name: np.full(SAMPLES, 1000 + k) for k, name in enumerate(cpu)}
    return MonitorLog(list(cpu), i * 0.5, 1.7e9 + i * 0.5, pid, values)


def run_log(mode: str, repeat: int) -> MonitorLog:
    a, b, rss = LOCALIZER[mode][repeat - 1]
    cpu = {"/ndt_localizer": (a, b), **{name: (c, 0.0) for name, c in HELPERS[mode].items()}}
    return ramp_log(cpu, {"/ndt_localizer": rss, **{name: 10.0 for name in HELPERS[mode]}})


def line(t: np.ndarray, y: float = 0.0):
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    return make_trajectory(t, np.stack([t - t[0], 0 * t + y, 0 * t], axis=1), quat)


def hand_median(values: list[float]) -> float:
    """The median of three: the middle one."""
    assert len(values) == 3
    return sorted(values)[1]


@pytest.fixture
def repeated(tmp_path):
    """Three runs of global and grid_puzzle in the runner's layout: OUT/<mode>/ the first, repeat_<r>/ the others."""
    t = 100.0 + np.arange(50) * 0.1
    for mode in MODES:
        write_tum(run_dir(tmp_path, mode) / "trajectory.tum", line(t, 0.0 if mode == "global" else 0.02))
        for repeat in (1, 2, 3):
            write_csv(run_dir(tmp_path, mode, repeat) / "monitor.csv", run_log(mode, repeat))
    info = RunInfo(scenario={"name": "synthetic"}, modes=MODES, roles=ROLES, max_diff_s=0.01, repeats=3)
    write_run_info(tmp_path, info)
    return tmp_path


def test_modes_run_interleaved_round_by_round():
    modes = ["global", "grid_puzzle", "grid_puzzle_rospy"]
    runs = interleaved_runs(modes, 3)
    assert runs[:4] == [(1, "global"), (1, "grid_puzzle"), (1, "grid_puzzle_rospy"), (2, "global")]
    # Slot k holds round k // M + 1 and mode k % M: each round runs every mode once, in the given order.
    assert len(runs) == 9
    for k, (repeat, mode) in enumerate(runs):
        assert (repeat, mode) == (k // len(modes) + 1, modes[k % len(modes)])
    assert interleaved_runs(modes, 1) == [(1, m) for m in modes]
    with pytest.raises(ValueError, match="repeats must be >= 1"):
        interleaved_runs(modes, 0)


def test_figures_are_medians_over_the_runs_with_their_spread(repeated):
    summary = build_report(repeated)
    assert json.loads((repeated / "summary.json").read_text()) == json.loads(json.dumps(summary))
    assert summary["repeats"]["count"] == 3
    cpu_means, rss_means = {}, {}
    for mode in MODES:
        res = summary["modes"][mode]["resources"]
        runs = LOCALIZER[mode]
        helpers_cpu, helpers_rss = sum(HELPERS[mode].values()), 10.0 * len(HELPERS[mode])
        cpu_means[mode] = [a + 10 * b for a, b, _ in runs]
        rss_means[mode] = [rss * MIB for _, _, rss in runs]
        paper = res["paper"]
        assert paper["processes"] == ["/ndt_localizer"]
        assert paper["cpu_percent"]["mean"] == pytest.approx(hand_median(cpu_means[mode]), abs=1e-9)
        assert paper["cpu_percent"]["p95"] == pytest.approx(hand_median([a + 19 * b for a, b, _ in runs]), abs=1e-9)
        assert paper["cpu_percent"]["max"] == pytest.approx(hand_median([a + 20 * b for a, b, _ in runs]), abs=1e-9)
        assert paper["rss_bytes"]["mean"] == hand_median(rss_means[mode])
        total = res["total"]
        assert total["cpu_percent"]["mean"] == pytest.approx(hand_median(cpu_means[mode]) + helpers_cpu, abs=1e-9)
        assert total["rss_bytes"]["mean"] == hand_median(rss_means[mode]) + helpers_rss * MIB
        # Each run's own figures, in run order.
        per_repeat = summary["modes"][mode]["per_repeat"]
        assert [p["repeat"] for p in per_repeat] == [1, 2, 3]
        got = [p["resources"]["paper"]["cpu_percent"]["mean"] for p in per_repeat]
        np.testing.assert_allclose(got, cpu_means[mode], atol=1e-9)
    # The spread: the runs' CPU means with their range, and each run over the global map's run of its round.
    spread = summary["repeats"]["spread"]["grid_puzzle"]["paper"]
    np.testing.assert_allclose(spread["cpu_percent"]["means"], cpu_means["grid_puzzle"], atol=1e-9)
    assert spread["cpu_percent"]["min"] == pytest.approx(min(cpu_means["grid_puzzle"]), abs=1e-9)
    assert spread["cpu_percent"]["max"] == pytest.approx(max(cpu_means["grid_puzzle"]), abs=1e-9)
    cpu_ratios = [g / b for g, b in zip(cpu_means["grid_puzzle"], cpu_means["global"])]
    rss_ratios = [g / b for g, b in zip(rss_means["grid_puzzle"], rss_means["global"])]
    np.testing.assert_allclose(spread["cpu_percent"]["vs_baseline"]["per_repeat"], cpu_ratios, rtol=1e-12)
    assert spread["cpu_percent"]["vs_baseline"]["min"] == pytest.approx(min(cpu_ratios), rel=1e-12)
    assert spread["rss_bytes"]["vs_baseline"]["max"] == pytest.approx(max(rss_ratios), rel=1e-12)
    assert summary["repeats"]["spread"]["global"]["paper"]["cpu_percent"]["vs_baseline"]["per_repeat"] == [1.0] * 3
    # The reductions compare the medians.
    red = summary["reductions"]["grid_puzzle"]["paper"]["cpu_percent"]["mean"]["absolute"]
    assert red == pytest.approx(hand_median(cpu_means["grid_puzzle"]) - hand_median(cpu_means["global"]), abs=1e-9)
    # The first table: how many runs, the medians, the CPU range and the per-round ratio range.
    report = (repeated / "report.md").read_text()
    first = report.split("## Grid puzzle against the global map")[1].split("\n## ")[0]
    assert "Each mode ran 3 times, interleaved" in first
    g_cpu, n_cpu = hand_median(cpu_means["global"]), hand_median(cpu_means["grid_puzzle"])
    g_rss, n_rss = hand_median(rss_means["global"]), hand_median(rss_means["grid_puzzle"])
    lo, hi = min(cpu_means["grid_puzzle"]), max(cpu_means["grid_puzzle"])
    row = (
        f"| paper | grid puzzle | /ndt_localizer | {n_cpu:.1f} | {lo:.1f}–{hi:.1f} | {n_cpu / g_cpu:.2f} x "
        f"| {min(cpu_ratios):.2f}–{max(cpu_ratios):.2f} | {n_rss / MIB:.1f} | {n_rss / g_rss:.2f} x "
        f"| {min(rss_ratios):.2f}–{max(rss_ratios):.2f} |"
    )
    assert row in first, first


def test_a_run_json_without_repeats_reads_the_first_runs_alone(repeated):
    # As an experiment directory written before --repeats existed: one run per mode, its figures unchanged.
    info = json.loads((repeated / "run.json").read_text())
    del info["repeats"]
    (repeated / "run.json").write_text(json.dumps(info))
    summary = build_report(repeated)
    assert summary["repeats"]["count"] == 1
    for mode in MODES:
        single = mode_resources(mode, ROLES[mode], read_csv(repeated / mode / "monitor.csv"))
        assert summary["modes"][mode]["resources"] == single
        assert summary["modes"][mode]["per_repeat"][0]["resources"] == single
    report = (repeated / "report.md").read_text()
    assert "interleaved" not in report
    assert (
        "| protocol | mode | processes | CPU mean [% of one core] | vs global | RSS mean [MiB] | vs global |" in report
    )


def test_an_even_number_of_runs_takes_the_mean_of_the_middle_two():
    logs = [run_log("global", r) for r in (1, 2)]
    median = median_resources([mode_resources("global", ROLES["global"], log) for log in logs])
    assert median["paper"]["cpu_percent"]["mean"] == pytest.approx((9.5 + 10.2) / 2, abs=1e-9)
    assert median["paper"]["cpu_percent"]["samples"] == SAMPLES
    assert median_of([3.0, None, 1.0]) is None and value_range([2.0, None]) == {"min": None, "max": None}


def test_runner_runs_rounds_in_turn_each_into_its_own_directory(tmp_path, monkeypatch):
    """run_experiment with run_mode replaced by a stand-in that writes a run's outputs: the runs come in the
    interleaved order, each into its own directory, the empty-map runs only in the first round; the report reads
    each run's monitor output as that mode's repeat."""
    calls = []

    def fake_run_mode(cfg, mode, inputs, start):
        calls.append((mode, inputs.out))
        inputs.out.mkdir(parents=True, exist_ok=True)
        # The k-th run of a mode (empty-map runs not counted) has its localizer at 10 k % of a core.
        k = sum(1 for m, out in calls if m == mode and out.name != "empty_map")
        cpu = {"/ndt_localizer": (10.0 * k, 0.0), **{name: (1.0, 0.0) for name in HELPERS[mode]}}
        write_csv(inputs.out / "monitor.csv", ramp_log(cpu, {name: 100.0 for name in cpu}))
        if inputs.record:
            write_tum(inputs.out / "trajectory.tum", line(100.0 + np.arange(20) * 0.1))
        return runner.ModeOutcome(mode, "http://localhost:1", ROLES[mode], list(cpu), [], [])

    monkeypatch.setattr(runner, "run_mode", fake_run_mode)
    monkeypatch.setattr(runner, "write_empty_map", lambda d, s: (tmp_path / "empty.pcd", tmp_path / "empty_tiles"))
    monkeypatch.setattr(runner, "first_scan_stamp", lambda bag: None)
    (tmp_path / "bag.bag").write_bytes(b"")
    write_pcd(tmp_path / "map.pcd", np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
    out = tmp_path / "out"
    cfg = ExperimentConfig(
        out_dir=out, bag=tmp_path / "bag.bag", global_map=tmp_path / "map.pcd", modes=MODES,
        initial_pose=[0.0] * 6, empty_map_s=5.0, repeats=3,
    )  # fmt: skip
    summary = runner.run_experiment(cfg, tiles=None, storage=None)
    assert calls == [
        ("global", out / "global"),
        ("global", out / "global" / "empty_map"),
        ("grid_puzzle", out / "grid_puzzle"),
        ("grid_puzzle", out / "grid_puzzle" / "empty_map"),
        ("global", out / "global" / "repeat_2"),
        ("grid_puzzle", out / "grid_puzzle" / "repeat_2"),
        ("global", out / "global" / "repeat_3"),
        ("grid_puzzle", out / "grid_puzzle" / "repeat_3"),
    ]
    outcomes = json.loads((out / "run.json").read_text())["extra"]["outcomes"]
    assert [(o["mode"], o["repeat"]) for o in outcomes] == [
        ("global", 1), ("global", 1), ("grid_puzzle", 1), ("grid_puzzle", 1),
        ("global", 2), ("grid_puzzle", 2), ("global", 3), ("grid_puzzle", 3),
    ]  # fmt: skip
    for mode in MODES:
        per_repeat = [p["resources"]["paper"]["cpu_percent"]["mean"] for p in summary["modes"][mode]["per_repeat"]]
        assert per_repeat == [10.0, 20.0, 30.0]
        assert summary["modes"][mode]["resources"]["paper"]["cpu_percent"]["mean"] == 20.0
