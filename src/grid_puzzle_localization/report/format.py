"""How the report writes modes and figures: mode titles, MiB, changes and ratios ("–" for a missing figure)."""

from __future__ import annotations

from collections.abc import Mapping

MIB = 1024.0 * 1024.0
MODE_TITLES = {
    "global": "global map",
    "grid_puzzle": "grid puzzle",
    "grid_puzzle_rospy": "grid puzzle, the paper's setup (rospy provider)",
    "block_map": "block map",
}


def mode_title(mode: str) -> str:
    return MODE_TITLES.get(mode, mode)


def num(value: float | None, fmt: str = ".1f", suffix: str = "") -> str:
    return "–" if value is None else f"{value:{fmt}}{suffix}"


def mib(value: float | None) -> str:
    return num(None if value is None else value / MIB, ".1f")


def times(value: float | None) -> str:
    """A ratio as "0.42 x"."""
    return num(value, ".2f", " x")


def change(change: Mapping | None, scale: float = 1.0, unit: str = "") -> str:
    """An evaluation.resources.reduction as "+1.0 unit (+5.0 %)"."""
    if not change or change.get("absolute") is None:
        return "–"
    rel = change.get("relative_percent")
    rel_text = "" if rel is None else f" ({rel:+.1f} %)"
    return f"{change['absolute'] / scale:+.1f}{unit}{rel_text}"
