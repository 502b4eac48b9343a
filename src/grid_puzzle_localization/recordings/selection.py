"""Which scans of a recording build the map and which are played, and the faults cut into the played ones
(scans dropped at random, gaps of a few seconds) to test a localizer against what real recordings hold."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import UserError

PLAY_CHOICES = ("rest", "all")


@dataclass(frozen=True)
class Selection:
    """Scans are numbered from 0 in file order. ``first``/``last`` (inclusive) bound the scans used at all;
    the map is built from every ``map_every``-th of them (counting from ``first``) or from ``map_range``
    (inclusive), or comes from elsewhere (both None, ``own_map``). ``play`` is ``rest`` (the scans not in
    the map) or ``all``."""

    first: int = 0
    last: int | None = None
    map_every: int | None = None
    map_range: tuple[int, int] | None = None
    own_map: bool = False  # the map is given as a file; every selected scan is played
    play: str = "rest"
    drop_fraction: float = 0.0  # of the played scans (never the first), at random
    gaps: tuple[tuple[float, float], ...] = ()  # (start after the first played scan, length) [s]
    seed: int = 0  # of the random drops


@dataclass(frozen=True)
class Plan:
    used: np.ndarray  # indices of the scans in [first, last]
    mapped: np.ndarray  # indices of the scans that build the map
    played: np.ndarray  # indices of the scans written to the bag, increasing
    dropped: np.ndarray  # played scans removed at random
    cut: np.ndarray  # played scans removed by the gaps


def _check(sel: Selection, count: int) -> tuple[int, int]:
    last = count - 1 if sel.last is None else sel.last
    if not (0 <= sel.first <= last < count):
        raise UserError(f"--first {sel.first} / --last {last} must satisfy 0 <= first <= last < {count} (the scans)")
    given = [sel.map_every is not None, sel.map_range is not None, sel.own_map]
    if sum(given) != 1:
        raise UserError("choose where the map comes from: --map-every N, --map-range A B, or --map FILE")
    if sel.map_every is not None and sel.map_every < 1:
        raise UserError(f"--map-every must be at least 1 (got {sel.map_every})")
    if sel.map_range is not None and not (sel.first <= sel.map_range[0] <= sel.map_range[1] <= last):
        raise UserError(f"--map-range {sel.map_range[0]} {sel.map_range[1]} must lie within scans {sel.first}-{last}")
    if sel.play not in PLAY_CHOICES:
        raise UserError(f"--play must be one of {', '.join(PLAY_CHOICES)} (got {sel.play})")
    if not (0.0 <= sel.drop_fraction < 1.0):
        raise UserError(f"--drop-fraction must be in [0, 1) (got {sel.drop_fraction})")
    for start, length in sel.gaps:
        if not (math.isfinite(start) and math.isfinite(length) and start > 0 and length > 0):
            raise UserError(f"--gap {start} {length}: start and length must be positive seconds")
    return sel.first, last


def plan(sel: Selection, times: np.ndarray) -> Plan:
    """The scans to map and to play for ``times`` (one per scan, increasing) [s]."""
    first, last = _check(sel, len(times))
    used = np.arange(first, last + 1)
    if sel.own_map:
        mapped = np.empty(0, dtype=np.int64)
    elif sel.map_every is not None:
        mapped = used[:: sel.map_every]
    else:
        mapped = np.arange(sel.map_range[0], sel.map_range[1] + 1)
    played = used if sel.play == "all" or sel.own_map else np.setdiff1d(used, mapped)
    if len(played) == 0:
        raise UserError("no scan is left to play: every selected scan builds the map; use --play all")
    cut_mask = np.zeros(len(played), dtype=bool)
    t0 = times[played[0]]
    for start, length in sel.gaps:
        cut_mask |= (times[played] >= t0 + start) & (times[played] < t0 + start + length)
    rng = np.random.default_rng(sel.seed)
    candidates = np.flatnonzero(~cut_mask)[1:]  # the first played scan carries the initial pose
    n_drop = round(sel.drop_fraction * len(played))
    drop_mask = np.zeros(len(played), dtype=bool)
    drop_mask[rng.choice(candidates, size=min(n_drop, len(candidates)), replace=False)] = True
    kept = played[~cut_mask & ~drop_mask]
    if len(kept) < 2:
        raise UserError("fewer than 2 scans are left to play after the drops and gaps; drop or cut less")
    return Plan(used, mapped, kept, played[drop_mask], played[cut_mask])
