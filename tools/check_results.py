#!/usr/bin/env python3
"""Reads the JUnit XML files of gtest, pytest and rostest under a results directory and prints
"N passed, N failed, N skipped". Exits 1 when a suite wrote no result file, ran no test, or has a
failure or error."""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path


def count(path: Path) -> tuple[int, int, int]:
    """(passed, failed, skipped) over the <testcase> elements of one JUnit file. A suite whose
    errors/failures attributes exceed its failing test cases (rostest's record of a test node that
    crashed or timed out before reporting any case) counts the difference as failures."""
    passed = failed = skipped = 0
    root = ET.parse(path).getroot()
    for suite in root.iter("testsuite"):
        suite_failed = 0
        for case in suite.findall("testcase"):
            if case.find("failure") is not None or case.find("error") is not None:
                suite_failed += 1
            elif case.find("skipped") is not None:
                skipped += 1
            else:
                passed += 1
        declared = int(suite.get("errors", 0) or 0) + int(suite.get("failures", 0) or 0)
        failed += max(suite_failed, declared)
    return passed, failed, skipped


def main() -> int:
    results, suites = Path(sys.argv[1]), sys.argv[2:]
    ok = True
    totals = [0, 0, 0]
    for suite in suites:
        files = sorted((results / suite).rglob("*.xml"))
        suite_totals = [0, 0, 0]
        for f in files:
            try:
                for i, n in enumerate(count(f)):
                    suite_totals[i] += n
            except ET.ParseError as err:
                print(f"check_results: {f} is not valid XML ({err}); counting it as a failure")
                suite_totals[1] += 1
        print(f"{suite}: {suite_totals[0]} passed, {suite_totals[1]} failed, {suite_totals[2]} skipped")
        if not files or sum(suite_totals) == 0:
            print(f"check_results: {suite} produced no test results in {results / suite}")
            ok = False
        ok = ok and suite_totals[1] == 0
        totals = [a + b for a, b in zip(totals, suite_totals)]
    print(f"{totals[0]} passed, {totals[1]} failed, {totals[2]} skipped")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
