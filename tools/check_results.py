#!/usr/bin/env python3
"""Reads the JUnit XML files of gtest, pytest and rostest under a results directory and prints
"N passed, N failed, N skipped", then a line for each failing test. Writes those lines to failed.txt in the
results directory too, so that a long log can repeat them at its end. Exits 1 when a suite wrote no result
file, ran no test, or has a failure or error."""

from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path


def _first_line(case: ET.Element) -> str:
    """The first line of a failing test case's message, or of its text when it has no message."""
    for tag in ("failure", "error"):
        found = case.find(tag)
        if found is not None:
            text = found.get("message") or found.text or ""
            return text.strip().splitlines()[0][:200] if text.strip() else tag
    return ""


def count(path: Path) -> tuple[int, int, int, list[str]]:
    """(passed, failed, skipped, failing test names) over the <testcase> elements of one JUnit file. A
    suite whose errors/failures attributes exceed its failing test cases (rostest's record of a test node
    that crashed or timed out before reporting any case) counts the difference as failures, named by the
    suite."""
    passed = failed = skipped = 0
    names = []
    root = ET.parse(path).getroot()
    for suite in root.iter("testsuite"):
        suite_failed = 0
        for case in suite.findall("testcase"):
            message = _first_line(case)
            if message:
                suite_failed += 1
                names.append(f"{case.get('classname', '')}.{case.get('name', '')}: {message}")
            elif case.find("skipped") is not None:
                skipped += 1
            else:
                passed += 1
        declared = int(suite.get("errors", 0) or 0) + int(suite.get("failures", 0) or 0)
        if declared > suite_failed:
            names.append(f"{suite.get('name', path.stem)}: {declared - suite_failed} failed without a test case")
        failed += max(suite_failed, declared)
    return passed, failed, skipped, names


def main() -> int:
    results, suites = Path(sys.argv[1]), sys.argv[2:]
    ok = True
    totals = [0, 0, 0]
    failing = []
    for suite in suites:
        files = sorted((results / suite).rglob("*.xml"))
        suite_totals = [0, 0, 0]
        for f in files:
            try:
                *counts, names = count(f)
            except ET.ParseError as err:
                print(f"check_results: {f} is not valid XML ({err}); counting it as a failure")
                counts, names = [0, 1, 0], ["is not valid XML"]
            suite_totals = [a + b for a, b in zip(suite_totals, counts)]
            failing += [f"FAILED {suite} {f.relative_to(results / suite)}: {name}" for name in names]
        print(f"{suite}: {suite_totals[0]} passed, {suite_totals[1]} failed, {suite_totals[2]} skipped")
        if not files or sum(suite_totals) == 0:
            print(f"check_results: {suite} produced no test results in {results / suite}")
            ok = False
        ok = ok and suite_totals[1] == 0
        totals = [a + b for a, b in zip(totals, suite_totals)]
    print(f"{totals[0]} passed, {totals[1]} failed, {totals[2]} skipped")
    print("\n".join(failing) if failing else "no test failed")
    listing = results / "failed.txt"
    listing.with_suffix(".tmp").write_text("".join(line + "\n" for line in failing))
    os.replace(listing.with_suffix(".tmp"), listing)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
