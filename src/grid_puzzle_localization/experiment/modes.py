"""The experiment's map modes and how each one is launched. Pure: the evaluation and the report use the
names too."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LaunchMode:
    """What localization.launch gets for a mode: its ``mode`` and, for the grid puzzle, its ``provider``."""

    mode: str
    provider: str | None = None  # nodelet (in the localizer's manager) | rospy (a process of its own)


# grid_puzzle is what a user gets (the provider nodelet in the localizer's nodelet manager);
# grid_puzzle_rospy is the paper's setup (the provider as a rospy node, a process of its own).
LAUNCH_MODES: dict[str, LaunchMode] = {
    "global": LaunchMode("global"),
    "grid_puzzle": LaunchMode("grid_puzzle", "nodelet"),
    "grid_puzzle_rospy": LaunchMode("grid_puzzle", "rospy"),
    "block_map": LaunchMode("block_map"),
}
MODES = tuple(LAUNCH_MODES)
GRID_PUZZLE_MODES = ("grid_puzzle", "grid_puzzle_rospy")  # the modes that play the tiles
DEFAULT_MODES = ("global", *GRID_PUZZLE_MODES)
EMPTY_MAP_MODES = DEFAULT_MODES  # the modes whose floor an empty-map run measures


def interleaved_runs(modes: list[str] | tuple[str, ...], repeats: int) -> list[tuple[int, str]]:
    """The order of an experiment's runs as (repeat, mode), repeat from 1: every mode once per round, the rounds in
    turn (global, grid_puzzle, global, grid_puzzle, ...), so a slow spell of the machine falls on every mode
    alike rather than on all the repeats of one."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1 (got {repeats})")
    return [(repeat, mode) for repeat in range(1, repeats + 1) for mode in modes]
