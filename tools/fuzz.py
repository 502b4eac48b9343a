#!/usr/bin/env python3
"""Runs the fuzz targets of test/fuzz (libFuzzer C++ binaries built by `make fuzz`, atheris Python
scripts) and prints one JSON object per target: executions, corpus size and findings. Each target first
replays its regression inputs (test/fuzz/regressions), then fuzzes for --seconds from its seeds and a
corpus kept in build/fuzz/corpus between runs. A finding is any crash, sanitizer report, uncaught
exception, hang (> --timeout s per input) or allocation over --malloc-mb; its input is saved under
build/fuzz/findings/<target>/. --junit writes the results as a JUnit file for tools/run_tests.sh.
Exit status 1 when anything was found."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FUZZ = ROOT / "test" / "fuzz"


@dataclass(frozen=True)
class Target:
    name: str
    language: str  # "c++" (libFuzzer + ASan + UBSan) or "python" (atheris)
    program: str  # binary name in the fuzz build dir, or script in test/fuzz
    inputs: str  # name of the seeds/ and regressions/ subdirectories

    def command(self, build: Path) -> list[str]:
        if self.language == "c++":
            return [str(build / self.program)]
        return [sys.executable, str(FUZZ / self.program)]


TARGETS = (
    Target("cpp_pcd_reader", "c++", "fuzz_pcd_reader", "pcd"),
    Target("cpp_point_cloud_msg", "c++", "fuzz_point_cloud_msg", "point_cloud_msg"),
    Target("py_pcd_header", "python", "fuzz_pcd_header.py", "pcd"),
    Target("py_pcd_reader", "python", "fuzz_pcd_reader.py", "pcd"),
    Target("py_tile_index", "python", "fuzz_tile_index.py", "tile_index"),
)


def environment(scratch: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), str(FUZZ), env.get("PYTHONPATH", "")])
    env["TMPDIR"] = str(scratch)  # the harnesses' scratch files: tmpfs, a file per input on disk is 10x slower
    env.setdefault("ASAN_OPTIONS", "detect_leaks=1:allocator_may_return_null=0")
    env.setdefault("UBSAN_OPTIONS", "print_stacktrace=1:halt_on_error=1")
    return env


def run_target(target: Target, args: argparse.Namespace) -> dict:
    work, findings = args.work, args.work / "findings" / target.name
    corpus = work / "corpus" / target.name
    for d in (corpus, findings):
        d.mkdir(parents=True, exist_ok=True)
    limits = [f"-timeout={args.timeout}", f"-rss_limit_mb={args.rss_mb}", f"-malloc_limit_mb={args.malloc_mb}"]
    base = ["nice", "-n", str(args.nice), *target.command(args.build), *limits, f"-artifact_prefix={findings}/"]
    scratch = tempfile.TemporaryDirectory(prefix="gpl_fuzz_", dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
    env = environment(Path(scratch.name))
    regressions = sorted((FUZZ / "regressions" / target.inputs).glob("*"))
    found: list[str] = []
    if regressions:
        replay = subprocess.run(base + [str(p) for p in regressions], env=env, capture_output=True, text=True)
        if replay.returncode != 0:
            found.append(f"regression input fails again (exit status {replay.returncode}): {last_error(replay.stderr)}")
    started = time.monotonic()
    options = ["-print_final_stats=1", f"-max_total_time={args.seconds}"]
    fuzz = subprocess.run(
        [*base, *options, str(corpus), str(FUZZ / "seeds" / target.inputs)],
        env=env,
        capture_output=True,
        text=True,
    )
    seconds = time.monotonic() - started
    scratch.cleanup()
    (work / f"{target.name}.log").write_text(fuzz.stderr)
    if fuzz.returncode != 0:
        found.append(f"exit status {fuzz.returncode}: {last_error(fuzz.stderr)}")
    executions = stat(fuzz.stderr, r"stat::number_of_executed_units:\s*(\d+)") or stat(fuzz.stderr, r"#(\d+)\s")
    return {
        "target": target.name,
        "language": target.language,
        "seconds": round(seconds, 1),
        "executions": executions,
        "executions_per_s": round(executions / seconds, 1) if seconds > 0 else 0,
        "corpus_files": sum(1 for _ in corpus.iterdir()),
        "regressions_replayed": len(regressions),
        "findings": found,
        "artifacts": re.findall(r"Test unit written to (\S+)", fuzz.stderr),
    }


def stat(log: str, pattern: str) -> int:
    values = re.findall(pattern, log)
    return int(values[-1]) if values else 0


def last_error(log: str) -> str:
    """The sanitizer's or libFuzzer's one-line verdict (or the Python exception) from a run's stderr."""
    lines = [line.strip() for line in log.splitlines()]
    for key in ("Error:", "SUMMARY:", "ERROR:"):
        hits = [line for line in lines if key in line]
        if hits:
            return hits[-1][:300]
    return (lines[-1] if lines else "exit status != 0")[:300]


def write_junit(results: list[dict], path: Path) -> None:
    suite = ET.Element("testsuite", name="fuzz", tests=str(len(results)))
    for r in results:
        case = ET.SubElement(suite, "testcase", classname="fuzz", name=r["target"], time=str(r["seconds"]))
        if r["findings"]:
            ET.SubElement(case, "failure", message="; ".join(r["findings"])).text = json.dumps(r)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(suite).write(path, encoding="utf-8", xml_declaration=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=int, default=5, help="fuzzing time per target [s]")
    parser.add_argument("--targets", nargs="*", default=[t.name for t in TARGETS], choices=[t.name for t in TARGETS])
    parser.add_argument("--parallel", type=int, default=1, help="targets run at the same time")
    parser.add_argument("--nice", type=int, default=10, help="niceness of the fuzzers (the cores are shared)")
    parser.add_argument("--timeout", type=int, default=10, help="seconds one input may take")
    parser.add_argument("--rss-mb", type=int, default=2048)
    parser.add_argument("--malloc-mb", type=int, default=1024, help="largest single allocation allowed [MB]")
    parser.add_argument("--build", type=Path, default=ROOT / "build" / "build_fuzz", help="the C++ fuzz build dir")
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "fuzz", help="corpora, findings, logs")
    parser.add_argument("--junit", type=Path, help="also write the results as a JUnit XML file")
    args = parser.parse_args()
    targets = [t for t in TARGETS if t.name in args.targets]
    with ThreadPoolExecutor(max_workers=max(1, args.parallel)) as pool:
        results = list(pool.map(lambda t: run_target(t, args), targets))
    for r in results:
        print(json.dumps(r), flush=True)
    if args.junit:
        write_junit(results, args.junit)
    return 1 if any(r["findings"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
