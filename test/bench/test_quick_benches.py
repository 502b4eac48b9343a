"""Every `make bench-*` target in its quick mode (a few seconds on tiny inputs, no ../shared data), so a broken
benchmark fails `make test` (tools/run_tests.sh bench). Each must exit 0 and print one JSON object per line.
The figures are not judged here: speed is measured by the full benchmarks, never by tests."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("GPL_WS", "")) / "devel" / "lib" / "grid_puzzle_localization"

# The one list of benchmarks: make target -> its quick command.
QUICK = {
    "bench-tiling": [sys.executable, str(ROOT / "bench/bench_tiling.py"), "--quick"],
    "bench-provider": [sys.executable, str(ROOT / "bench/bench_provider.py"), "--quick"],
    "bench-ndt": [str(BIN / "bench_ndt"), "--quick"],
    "bench-map-store": [sys.executable, str(ROOT / "bench/bench_map_store.py"), "--quick"],
    "bench-localizer": [sys.executable, str(ROOT / "bench/bench_localizer.py"), "--quick"],
    "bench-sim": [sys.executable, str(ROOT / "bench/bench_sim.py"), "--quick"],
    "bench-blocks": [sys.executable, str(ROOT / "bench/bench_blocks.py"), "--quick"],
    "bench-monitor": [sys.executable, str(ROOT / "bench/bench_monitor.py"), "--quick"],
    "bench-scaling": [sys.executable, str(ROOT / "bench/bench_scaling.py"), "--quick"],
    "bench-global-localization": [sys.executable, str(ROOT / "bench/bench_global_localization.py"), "--quick"],
}
TIMEOUT_S = 300  # generous on a shared 2-core machine; a quick mode takes seconds


def make_bench_targets() -> set[str]:
    return set(re.findall(r"^(bench-[\w-]+):", (ROOT / "Makefile").read_text(), flags=re.MULTILINE))


def test_every_make_bench_target_has_a_quick_mode_here():
    assert make_bench_targets() == set(QUICK)


@pytest.mark.parametrize("target", sorted(QUICK))
def test_quick_mode_prints_json_lines(target, tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    run = subprocess.run(QUICK[target], cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    assert run.returncode == 0, f"{target} --quick failed ({run.returncode}):\n{run.stderr[-3000:]}"
    lines = [line for line in run.stdout.splitlines() if line.strip()]
    assert lines, f"{target} --quick printed nothing"
    for line in lines:
        row = json.loads(line)  # one JSON document per line, never an indented one over many
        assert isinstance(row, dict), f"{target} printed a line that is not a JSON object: {line}"
