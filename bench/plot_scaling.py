"""Plots `make bench-scaling`'s JSON lines: the localizer's peak RSS and its map memory against map area, global
map against grid puzzle tiles. Usage: python3 bench/plot_scaling.py RESULTS.jsonl OUT.png"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from grid_puzzle_localization.report.plots import new_figure, save_png
from grid_puzzle_localization.util.iteration import zip_equal

STYLE = {"global": ("tab:blue", "global map (pcd)"), "tiles": ("tab:orange", "grid puzzle (tiles by reference)")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    runs = [json.loads(line) for line in args.results.read_text().splitlines() if line.strip()]
    runs = [r for r in runs if r.get("bench") == "scaling"]
    fig = new_figure(9, 3.4)
    axes = fig.subplots(1, 2)
    panels = (("peak_rss_mb", "peak RSS"), ("map_memory_mb", "map memory"))
    for ax, (key, title) in zip_equal(axes, panels):
        for mode, (color, label) in STYLE.items():
            mine = sorted((r["area_km2"], r[key]) for r in runs if r["mode"] == mode)
            ax.plot([a for a, _ in mine], [v for _, v in mine], "o-", color=color, label=label)
        ax.set_xlabel("map area [km²] (1x, 4x, 16x the urban world)")
        ax.set_ylabel("MiB")
        ax.set_title(f"localizer {title}")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left")
    save_png(fig, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
