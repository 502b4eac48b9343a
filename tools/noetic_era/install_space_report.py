#!/usr/bin/env python3
"""The install-space run's figures (tools/noetic_era/inside.sh): the tracking error of `gpm experiment`'s grid puzzle
mode against the simulator's ground truth, and the installed files the run opened or executed (from `strace -f -e
trace=openat,execve`). Prints one JSON object; exits 1 when the error exceeds --max-rmse or nothing was posed.
Runs with only the standard library: the package's sources are moved away while it runs."""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

# strace lines of a call that succeeded: `PID openat(AT_FDCWD, "PATH", ...) = 3`, `PID execve("PATH", ...) = 0`
_OPENED = re.compile(r'^\d+\s+(?:openat\(\w+, |execve\()"([^"]+)".*\) = \d+')


def installed_files(trace: Path, prefix: str) -> list[str]:
    """The files under ``prefix`` that the traced processes opened or executed, relative to it."""
    found = set()
    for line in trace.read_text(errors="replace").splitlines():
        match = _OPENED.match(line)
        if match and match.group(1).startswith(prefix + "/"):
            found.add(str(Path(match.group(1)).relative_to(prefix)))
    return sorted(found)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("summary", type=Path, help="summary.json of gpm experiment")
    parser.add_argument("trace", type=Path, help="strace output")
    parser.add_argument("prefix", help="the install space")
    parser.add_argument("--max-rmse", type=float, required=True, help="bound on the translation RMSE [m]")
    parser.add_argument("--out", type=Path, required=True, help="where the JSON goes too")
    args = parser.parse_args()
    mode = json.loads(args.summary.read_text())["modes"]["grid_puzzle"]
    ape = mode["ape"]["translation_m"]
    report = {
        "install_space_run": "grid_puzzle",
        "poses": mode["poses"],
        "ape_rmse_m": round(ape["rmse"], 4),
        "ape_max_m": round(ape["max"], 4),
        "max_rmse_m": args.max_rmse,
        "installed_files_used": installed_files(args.trace, args.prefix.rstrip("/")),
    }
    text = json.dumps(report, indent=1)
    args.out.write_text(text + "\n")
    print(text)
    ok = mode["poses"] > 0 and ape["rmse"] <= args.max_rmse
    if not ok:
        print(f"install-space run: RMSE {ape['rmse']:.3f} m over {mode['poses']} poses, bound {args.max_rmse} m")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
