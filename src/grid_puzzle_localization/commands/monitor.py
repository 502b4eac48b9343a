"""`gpm monitor`: sample CPU and memory of ROS nodes (by name, through the ROS master) or of PIDs.

Runs for ``--duration`` seconds or until Ctrl-C, then writes the CSV and prints (and optionally
writes) the JSON summary."""

from __future__ import annotations

import argparse
import json
import sys

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.monitor.log import write_csv
from grid_puzzle_localization.monitor.sampler import DEFAULT_INTERVAL_S, Monitor, Target
from grid_puzzle_localization.monitor.stats import summarize
from grid_puzzle_localization.util.atomic import atomic_write


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("nodes", nargs="*", metavar="NODE", help="ROS node names, e.g. /ndt_localizer")
    parser.add_argument("--pid", type=int, action="append", default=[], help="a process id (repeatable)")
    parser.add_argument(
        "--interval", type=float, default=DEFAULT_INTERVAL_S, help="sampling period [s] (default %(default)s)"
    )
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: Ctrl-C)")
    parser.add_argument("--csv", default=None, help="write the samples to this CSV file")
    parser.add_argument("--json", default=None, help="write the summary to this JSON file (it is always printed)")


def _targets(args: argparse.Namespace) -> list[Target]:
    targets = [Target.from_pid(pid) for pid in args.pid]
    if args.nodes:
        # Only node names need ROS; PIDs work without it.
        from grid_puzzle_localization.ros.node_pids import node_target

        targets += [node_target(name) for name in args.nodes]
    if not targets:
        raise UserError("nothing to monitor: give ROS node names (e.g. /ndt_localizer) or --pid PID")
    return targets


def run(args: argparse.Namespace) -> int:
    if args.duration is not None and not args.duration > 0:
        raise UserError(f"--duration must be a positive number of seconds (got {args.duration})")
    monitor = Monitor(_targets(args), args.interval)
    print(f"gpm monitor: sampling {len(monitor.log().names)} process(es) every {args.interval} s", file=sys.stderr)
    try:
        log = monitor.run(args.duration)
    except KeyboardInterrupt:
        log = monitor.log()
    if args.csv:
        write_csv(args.csv, log)
    summary = summarize(log, args.interval)
    text = json.dumps(summary, indent=2)
    if args.json:
        with atomic_write(args.json) as f:
            f.write(text + "\n")
    print(text)
    return 0
