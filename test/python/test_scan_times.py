"""The per-scan time table the experiment's recorder writes: round trip, summary against numpy's closed
forms, clear errors for files that are not such a table, and the report's Time-per-scan section."""

from __future__ import annotations

import numpy as np
import pytest

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.scan_times import read_scan_times, summarize_scan_times, write_scan_times
from grid_puzzle_localization.report.markdown import scan_time_table


def test_round_trip_and_summary(tmp_path):
    rng = np.random.default_rng(4)
    rows = [(1700000000.0 + 0.1 * i, float(s), float(s) * 0.6) for i, s in enumerate(rng.uniform(5, 40, 200))]
    path = tmp_path / "scan_times.csv"
    write_scan_times(path, rows)
    data = read_scan_times(path)
    np.testing.assert_allclose(data, np.array(rows), atol=1e-4)
    summary = summarize_scan_times(data)
    times = np.array([r[1] for r in rows])
    assert summary["scans"] == 200
    assert summary["mean"] == pytest.approx(times.mean(), abs=1e-3)
    assert summary["median"] == pytest.approx(np.median(times), abs=1e-3)
    assert summary["p95"] == pytest.approx(np.percentile(times, 95), abs=1e-3)


def test_an_empty_run_has_no_figures(tmp_path):
    write_scan_times(tmp_path / "t.csv", [])
    assert summarize_scan_times(read_scan_times(tmp_path / "t.csv")) == {
        "scans": 0,
        "mean": None,
        "median": None,
        "p95": None,
    }


@pytest.mark.parametrize(
    "text, message",
    [
        ("t,a,b\n1,2,3\n", "not a scan-time table"),
        ("stamp_s,scan_time_ms,align_time_ms\n1,2\n", "t.csv"),
        ("stamp_s,scan_time_ms,align_time_ms\n1,x,3\n", "not three numbers"),
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
            "global": {"scan_time_ms": {"scans": 10, "mean": 12.25, "median": 11.0, "p95": 20.0}},
            "grid_puzzle": {"scan_time_ms": None},
        },
    }
    lines = scan_time_table(summary)
    assert lines[2] == "| global map | sliding_window | 10 | 12.2 | 11.0 | 20.0 |"
    assert len(lines) == 3
    assert scan_time_table({"scenario": {}, "modes": {"global": {}}}) == ["No per-scan times were recorded."]
