#!/usr/bin/env python3
"""`make reliability`: fuzzes every reader of outside data (tools/fuzz.py), runs the fault tests
(test/python/test_fault_*.py and the rostests in ROSTESTS, which record each fault's outcome)
and the replay of the inputs fuzzing found, then prints the report as a markdown table and writes it as
JSON lines to build/reliability/report.jsonl. Exit status 1 when a fuzzer found something or a fault
test failed."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROSTESTS = ("provider_respawn.test", "localizer_faults.test", "localizer_starvation.test")
FAULT_TESTS = (
    "test/python/test_fault_disk.py",
    "test/python/test_fuzz_regressions.py",
)


def fuzz(args: argparse.Namespace) -> list[dict]:
    if args.fuzz_results:
        return [json.loads(line) for line in args.fuzz_results.read_text().splitlines() if line.strip()]
    command = [sys.executable, str(ROOT / "tools" / "fuzz.py"), "--seconds", str(args.fuzz_seconds)]
    done = subprocess.run([*command, "--parallel", str(args.parallel), "--nice", "19"], capture_output=True, text=True)
    return [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]


def fault_tests() -> tuple[list[dict], list[dict]]:
    """(fault records, one verdict per test case) of a pytest run of FAULT_TESTS and of the ROSTESTS."""
    with tempfile.TemporaryDirectory() as tmp:
        records, junit = Path(tmp) / "faults.jsonl", Path(tmp) / "junit.xml"
        env = {**os.environ, "GPL_FAULT_REPORT": str(records)}
        subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={junit}", *FAULT_TESTS],
            cwd=ROOT,
            env=env,
            stdout=sys.stderr,
        )
        verdicts = []
        for case in ET.parse(junit).getroot().iter("testcase"):
            problem = case.find("failure") if case.find("failure") is not None else case.find("error")
            skipped = case.find("skipped")
            verdict = "failed" if problem is not None else "skipped" if skipped is not None else "passed"
            reason = (problem if problem is not None else skipped).get("message", "") if verdict != "passed" else ""
            verdicts.append({"test": case.get("name"), "verdict": verdict, "reason": reason[:200]})
        for name in ROSTESTS:
            command = ["rostest", f"--results-base-dir={tmp}/rostest", "grid_puzzle_localization", name]
            done = subprocess.run(command, cwd=ROOT, env=env, stdout=sys.stderr)
            verdicts.append({"test": name, "verdict": "passed" if done.returncode == 0 else "failed", "reason": ""})
        faults = [json.loads(line) for line in records.read_text().splitlines()] if records.exists() else []
    return faults, verdicts


def markdown(fuzzed: list[dict], faults: list[dict], verdicts: list[dict]) -> str:
    lines = ["| fuzz target | seconds | executions | executions/s | corpus | findings |", "|---|---|---|---|---|---|"]
    for r in fuzzed:
        found = "; ".join(r["findings"]) or "none"
        lines.append(
            f"| {r['target']} | {r['seconds']:.0f} | {r['executions']} | {r['executions_per_s']:.0f}"
            f" | {r['corpus_files']} | {found} |"
        )
    lines += ["", "| fault | outcome | recovery [s] | data lost |", "|---|---|---|---|"]
    for f in faults:
        recovery = "-" if f["recovery_s"] is None else f"{f['recovery_s']:g}"
        outcome = f["outcome"].replace("\n", " / ")  # stderr of several lines
        lines.append(f"| {f['fault']} | {outcome} | {recovery} | {f['data_lost']} |")
    lines += ["", "| test | verdict |", "|---|---|"]
    lines += [f"| {v['test']} | {v['verdict']} {v['reason']} |" for v in verdicts]
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fuzz-seconds", type=int, default=60, help="fuzzing time per target [s]")
    parser.add_argument("--parallel", type=int, default=2, help="fuzz targets run at the same time")
    parser.add_argument("--fuzz-results", type=Path, help="report these tools/fuzz.py JSON lines instead of fuzzing")
    args = parser.parse_args()
    fuzzed = fuzz(args)
    faults, verdicts = fault_tests()
    out = ROOT / "build" / "reliability" / "report.jsonl"
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w") as f:
        for kind, rows in (("fuzz", fuzzed), ("fault", faults), ("test", verdicts)):
            for row in rows:
                f.write(json.dumps({"kind": kind, **row}) + "\n")
    print(markdown(fuzzed, faults, verdicts))
    bad = any(r["findings"] for r in fuzzed) or any(v["verdict"] == "failed" for v in verdicts)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
