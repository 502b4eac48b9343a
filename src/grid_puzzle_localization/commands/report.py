"""`gpm report OUT_DIR`: (re)builds summary.json, report.md and plots/ of an experiment directory
written by `gpm experiment`, and prints the tables of the grid puzzle modes against the global map and the paper."""

from __future__ import annotations

import argparse

from grid_puzzle_localization.report.build import build_report
from grid_puzzle_localization.report.markdown import printed_tables


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out_dir", help="experiment directory (holds run.json and one directory per mode)")


def run(args: argparse.Namespace) -> int:
    summary = build_report(args.out_dir)
    print("\n".join(printed_tables(summary)))
    print(f"\nreport: {args.out_dir}/report.md, plots: {args.out_dir}/plots/")
    return 0
