"""The per-scan time table the experiment's recorder writes: round trip, summary against closed forms, the
accepted matches, tables without that column, clear errors for files that are not such a table, and the report's
Time-per-scan section."""

from __future__ import annotations

import numpy as np
import pytest

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.scan_times import (
    HEADER,
    accepted_stamps,
    read_scan_times,
    summarize_scan_times,
    write_scan_times,
)
from grid_puzzle_localization.report.markdown import scan_time_table


def test_round_trip_and_summary(tmp_path):
    # Scan times 1, 2, ..., 100 ms in shuffled order: mean and median 50.5; the q-th percentile, interpolated
    # linearly between order statistics, is 1 + 99 q / 100 (95.05 and 99.01); the maximum 100.
    rng = np.random.default_rng(4)
    ms = rng.permutation(np.arange(1, 101)).astype(float)
    # Iterations: the scan time's tens digit; hypotheses on every 4th scan, a search on every 10th; NVTL falling; the
    # map worker's CPU time from 3 s, 0.02 s more each scan: 1.98 s over the table.
    rows = [
        (
            1700000000.0 + 0.1 * i,
            s,
            0.6 * s,
            i % 3 != 0,
            int(s) // 10,
            2 * (i % 4 == 0),
            i % 10 == 0,
            2.5 - s / 100,
            3.0 + 0.02 * i,
        )
        for i, s in enumerate(ms)
    ]
    path = tmp_path / "scan_times.csv"
    write_scan_times(path, rows)
    data = read_scan_times(path)
    np.testing.assert_allclose(data, np.array(rows, dtype=float), atol=1e-4)
    summary = summarize_scan_times(data)
    slow = summary.pop("slow_scans")
    assert summary == pytest.approx(
        {"scans": 100, "mean": 50.5, "median": 50.5, "p95": 95.05, "p99": 99.01, "max": 100, "map_worker_cpu_s": 1.98}
    )
    np.testing.assert_allclose(accepted_stamps(data), [r[0] for r in rows if r[3]], atol=1e-6)
    # Over twice the median (101 ms): none. Iterations: 9 scans with 0, 10 each with 1..9, one with 10: median 5.
    # The same table with its times halved below 80 ms: the new median is 25.25 ms (0.5..39.5 and 80..100), and the
    # 21 scans of 80 ms and more are over twice it.
    assert slow["scans"] == 0 and slow["median_iterations"] is None and slow["median_iterations_all"] == 5.0
    halved = data.copy()
    halved[halved[:, 1] < 80, 1] /= 2
    slow = summarize_scan_times(halved)["slow_scans"]
    tail = [r for r in rows if r[1] >= 80]
    assert slow["scans"] == len(tail) == 21
    assert slow["with_hypotheses"] == sum(r[5] > 0 for r in tail)
    assert slow["with_search"] == sum(r[6] for r in tail)
    assert slow["median_iterations"] == np.median([r[4] for r in tail])


def test_a_table_without_the_accepted_column_is_read_and_says_nothing_of_it(tmp_path):
    (tmp_path / "t.csv").write_text("stamp_s,scan_time_ms,align_time_ms\n1.5,20,10\n1.7,30,12\n")
    data = read_scan_times(tmp_path / "t.csv")
    np.testing.assert_array_equal(data[:, :3], [[1.5, 20, 10], [1.7, 30, 12]])
    assert np.isnan(data[:, 3:]).all() and accepted_stamps(data) is None
    assert summarize_scan_times(data)["max"] == 30 and summarize_scan_times(data)["slow_scans"] is None


def test_a_table_without_what_the_match_did_is_read_and_says_nothing_of_it(tmp_path):
    (tmp_path / "t.csv").write_text("stamp_s,scan_time_ms,align_time_ms,match_accepted\n1.5,20,10,1\n1.7,30,12,0\n")
    data = read_scan_times(tmp_path / "t.csv")
    np.testing.assert_array_equal(accepted_stamps(data), [1.5])
    assert np.isnan(data[:, 4:]).all() and summarize_scan_times(data)["slow_scans"] is None


def test_a_table_without_the_nvtl_still_says_what_the_slow_scans_did(tmp_path):
    older = ",".join(HEADER.split(",")[:7])  # before the NVTL column
    (tmp_path / "t.csv").write_text(older + "\n1.5,10,8,1,4,0,0\n1.6,11,9,1,5,0,0\n1.7,40,38,1,20,4,0\n")
    data = read_scan_times(tmp_path / "t.csv")
    assert np.isnan(data[:, 7]).all()
    slow = summarize_scan_times(data)["slow_scans"]
    assert (slow["scans"], slow["with_hypotheses"], slow["median_iterations"]) == (1, 1, 20.0)


def test_an_empty_run_has_no_figures(tmp_path):
    write_scan_times(tmp_path / "t.csv", [])
    assert summarize_scan_times(read_scan_times(tmp_path / "t.csv")) == {
        "scans": 0,
        "mean": None,
        "median": None,
        "p95": None,
        "p99": None,
        "max": None,
        "slow_scans": None,
        "map_worker_cpu_s": None,
    }


@pytest.mark.parametrize(
    "text, message",
    [
        ("t,a,b\n1,2,3\n", "not a scan-time table"),
        ("stamp_s,scan_time_ms,align_time_ms\n1,2\n", "t.csv"),
        ("stamp_s,scan_time_ms,align_time_ms\n1,x,3\n", "not 3 numbers"),
        ("stamp_s,scan_time_ms,align_time_ms,match_accepted\n1,2,3\n", "expected 4"),
        (HEADER + "\n1,2,3,1,5,0,0\n", "expected 9"),
    ],
)
def test_bad_files_are_named(tmp_path, text, message):
    (tmp_path / "t.csv").write_text(text)
    with pytest.raises(UserError, match=message):
        read_scan_times(tmp_path / "t.csv")


def test_missing_file_is_named(tmp_path):
    with pytest.raises(UserError, match=r"cannot read .*nothing\.csv"):
        read_scan_times(tmp_path / "nothing.csv")


def test_report_table_lists_each_mode_with_its_fusion():
    summary = {
        "scenario": {"fusion": "sliding_window"},
        "modes": {
            "global": {
                "scan_time_ms": {
                    "scans": 10,
                    "mean": 12.25,
                    "median": 11.0,
                    "p95": 20.0,
                    "p99": 24.5,
                    "max": 25.0,
                    "slow_scans": {
                        "over_median": 2.0,
                        "scans": 2,
                        "with_hypotheses": 1,
                        "with_search": 0,
                        "median_iterations": 9.5,
                        "median_iterations_all": 3.0,
                    },
                }
            },
            "grid_puzzle_rospy": {
                "scan_time_ms": {"scans": 4, "mean": 5.0, "median": 5.0, "p95": 6.0, "p99": 6.0, "max": 6.0}
            },
            "grid_puzzle": {"scan_time_ms": None},
        },
    }
    lines = scan_time_table(summary)
    assert lines[2] == "| global map | sliding_window | 10 | 12.2 | 11.0 | 20.0 | 24.5 | 25.0 | 2 | 1 / 0 | 9.5 / 3.0 |"
    assert lines[3].endswith("| 6.0 | – | – | – |")  # an older summary: nothing said of its slow scans
    assert len(lines) == 4
    assert scan_time_table({"scenario": {}, "modes": {"global": {}}}) == ["No per-scan times were recorded."]


def test_a_table_without_the_map_workers_cpu_time_says_nothing_of_it(tmp_path):
    older = ",".join(HEADER.split(",")[:8])  # before the map worker's CPU column
    (tmp_path / "t.csv").write_text(older + "\n1.5,10,8,1,4,0,0,2.1\n1.6,11,9,1,5,0,0,2.2\n")
    data = read_scan_times(tmp_path / "t.csv")
    assert np.isnan(data[:, 8]).all()
    assert summarize_scan_times(data)["map_worker_cpu_s"] is None
