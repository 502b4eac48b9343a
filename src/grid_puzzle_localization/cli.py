"""`gpm`: the package's command line. Each subcommand lives in its own module, which provides
``add_arguments(parser)`` and ``run(args) -> int``; this file only dispatches."""

from __future__ import annotations

import argparse
import errno
import importlib
import signal
import sys
import threading

from grid_puzzle_localization.errors import UserError

# name -> (module, one-line help). Modules are imported lazily so `gpm tile` does not pay for
# matplotlib or rospy.
COMMANDS: dict[str, tuple[str, str]] = {
    "tile": ("commands.tile", "cut a global map PCD into grid puzzle tiles (or --verify a tiled map)"),
    "window": ("commands.window", "print the grid puzzle window (tiles to load) for a position, as JSON"),
    "simulate": ("commands.simulate", "generate a simulated LiDAR scenario: bag, ground truth, prior map"),
    "import": ("commands.import_scans", "turn a folder of scans with poses and times into an experiment directory"),
    "blocks": ("commands.blocks", "build keyframe-stitched block maps (block map paper, Algorithm 1)"),
    "submaps": ("commands.submaps", "cut a global map into fixed-size overlapping square submaps"),
    "storage": ("commands.storage", "storage overhead of global map, tiles, blocks and submaps"),
    "monitor": ("commands.monitor", "Sample CPU (percent of one core) and memory of ROS nodes or PIDs."),
    "experiment": ("commands.experiment", "Run the localizer per map mode on a bag, monitor it, and report."),
    "global-localize": (
        "commands.global_localize",
        "find a scan's pose on a map (tiles, PCD or blocks) without an initial guess; prints JSON",
    ),
    "report": ("commands.report", "Rebuild summary.json, report.md and plots of an experiment directory."),
    "map-drift": (
        "commands.map_drift",
        "split a simulated run's error into the prior map's own drift and the tracker's",
    ),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand, or, given ``command``, of that one only (the others are listed
    by name and help, so `gpm --help` still shows them) to import no more than the run needs."""
    parser = argparse.ArgumentParser(prog="gpm", description="Grid puzzle map localization tools.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_text) in COMMANDS.items():
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        if command is None or name == command:
            importlib.import_module(f"grid_puzzle_localization.{module}").add_arguments(cmd)
        cmd.set_defaults(_module=module)
    return parser


def _interrupt(_signum, _frame) -> None:
    raise KeyboardInterrupt  # a SIGTERM (kill, a CI timeout) cleans up as Ctrl-C does: child processes, temp files


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # The command is the first word (gpm itself has no options but -h), so only its module is imported.
    command = next((word for word in argv if not word.startswith("-")), None)
    args = build_parser(command).parse_args(argv)
    on_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _interrupt) if on_main_thread else None
    try:
        return _run(args)
    finally:
        if on_main_thread:
            signal.signal(signal.SIGTERM, previous)


def _run(args: argparse.Namespace) -> int:
    try:
        return int(importlib.import_module(f"grid_puzzle_localization.{args._module}").run(args) or 0)
    except UserError as err:
        print(f"gpm {args.command}: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # the file system's verdict (disk full, permissions): one line, as for bad input
        where = f" ({err.filename})" if err.filename else ""
        hint = "; free space there or write elsewhere" if err.errno in (errno.ENOSPC, errno.EDQUOT) else ""
        print(f"gpm {args.command}: error: {err.strerror or err}{where}{hint}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"gpm {args.command}: interrupted; no partial output was kept", file=sys.stderr)
        return 130
