"""tools/check_results.py: the JUnit files of a run judge it. A failing case, a rostest suite that declares more
errors than it has failing cases (a test node that died before reporting) and a suite with no result file each
fail the run, and each failing test is named on its own line and in failed.txt."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "check_results.py"

PASSING = (
    '<testsuite name="s" tests="2"><testcase classname="A" name="one"/><testcase classname="A" name="two"/></testsuite>'
)
FAILING = (
    '<testsuite name="s" tests="2" failures="1"><testcase classname="B" name="ok"/>'
    '<testcase classname="B" name="bad"><failure message="expected 3, got 4">trace</failure></testcase></testsuite>'
)
NODE_DIED = '<testsuite name="map_store_slow" tests="1" errors="2"><testcase classname="R" name="ran"/></testsuite>'
SKIPPED = '<testsuite name="s" tests="1"><testcase classname="C" name="later"><skipped/></testcase></testsuite>'


def run(results: Path, *suites: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(TOOL), str(results), *suites], capture_output=True, text=True)


def write(results: Path, suite: str, name: str, xml: str) -> None:
    (results / suite).mkdir(parents=True, exist_ok=True)
    (results / suite / name).write_text(xml)


def test_a_clean_run_passes_and_counts_every_case(tmp_path):
    write(tmp_path, "gtest", "a.xml", PASSING)
    write(tmp_path, "pytest", "b.xml", SKIPPED)
    done = run(tmp_path, "gtest", "pytest")
    assert done.returncode == 0, done.stdout
    assert "gtest: 2 passed, 0 failed, 0 skipped" in done.stdout
    assert "2 passed, 0 failed, 1 skipped" in done.stdout
    assert "no test failed" in done.stdout
    assert (tmp_path / "failed.txt").read_text() == ""


def test_each_failure_is_named_with_its_message(tmp_path):
    write(tmp_path, "gtest", "a.xml", PASSING)
    write(tmp_path, "rostest", "b.xml", FAILING)
    write(tmp_path, "rostest", "c.xml", NODE_DIED)
    done = run(tmp_path, "gtest", "rostest")
    assert done.returncode == 1
    assert "rostest: 2 passed, 3 failed, 0 skipped" in done.stdout
    expected = [
        "FAILED rostest b.xml: B.bad: expected 3, got 4",
        "FAILED rostest c.xml: map_store_slow: 2 failed without a test case",
    ]
    assert [line for line in done.stdout.splitlines() if line.startswith("FAILED")] == expected
    assert (tmp_path / "failed.txt").read_text().splitlines() == expected


def test_a_suite_without_results_fails_the_run(tmp_path):
    write(tmp_path, "gtest", "a.xml", PASSING)
    done = run(tmp_path, "gtest", "rostest")
    assert done.returncode == 1
    assert "rostest produced no test results" in done.stdout


def test_a_broken_file_counts_as_a_failure(tmp_path):
    write(tmp_path, "gtest", "a.xml", PASSING[:40])
    done = run(tmp_path, "gtest")
    assert done.returncode == 1
    assert "FAILED gtest a.xml: is not valid XML" in done.stdout
