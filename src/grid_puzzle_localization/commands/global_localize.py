"""`gpm global-localize`: finds a scan's pose on a map without an initial guess (branch-and-bound search
over x, y and yaw, then NDT; the block map paper's pose initialization). The map is a tile directory (or its
http(s):// URL, a map store: docs/map_store.md), a PCD file or a block directory; of a tile or block directory only
the files covering the search square (plus the scan's reach) are loaded (fetched into the map store's cache).
The search itself is the C++ ``global_localize`` program of the package; this command picks the files and prints
its answer as one JSON line."""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grid_puzzle_localization.blocks.store import INDEX_FILE as BLOCK_INDEX
from grid_puzzle_localization.blocks.store import read_block_index
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiles.directory import decode_key, open_tile_directory
from grid_puzzle_localization.tiles.grid import tile_index
from grid_puzzle_localization.tiles.map_store import MapStore, is_map_store_url

PROGRAM = "global_localize"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--map", required=True, help="tile directory (or its http(s):// URL), map PCD file or block directory"
    )
    parser.add_argument("--scan", required=True, help="scan PCD (x y z in the base frame)")
    parser.add_argument("--center", nargs=2, type=float, metavar=("X", "Y"), help="centre of the search [m]")
    parser.add_argument("--size", type=float, help="edge of the searched square [m] (default: the program's, 40)")
    parser.add_argument("--yaw-range", type=float, default=360.0, help="yaw interval searched [deg] (default 360)")
    parser.add_argument("--yaw-center", type=float, default=0.0, help="centre of the yaw interval [deg]")
    parser.add_argument("--grid-size", type=float, help="tile side [m] of a tile directory without an index")
    parser.add_argument("--threads", type=int, default=0, help="OpenMP threads, 0 = all cores")


@dataclass(frozen=True)
class MapFiles:
    files: list[Path]
    center: tuple[float, float] | None  # default search centre, None = the program's (its map's centre)


def find_program() -> Path:
    """The package's ``global_localize`` in the sourced catkin workspaces (where rosrun looks)."""
    try:
        from catkin.find_in_workspaces import find_in_workspaces
    except ImportError:
        raise UserError("catkin's Python package is missing: source the workspace (build/setup.bash)") from None
    found = find_in_workspaces(
        search_dirs=["libexec"], project="grid_puzzle_localization", path=PROGRAM, first_match_only=True
    )
    if not found:
        raise UserError(f"the {PROGRAM} program is not built: run `make build` and source build/setup.bash")
    return Path(found[0])


def program_defaults(program: Path) -> dict[str, float]:
    out = subprocess.run([str(program), "--print-config"], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def square(center: tuple[float, float], half: float) -> tuple[float, float, float, float]:
    return center[0] - half, center[0] + half, center[1] - half, center[1] + half


def tile_files(
    path: Path, grid_size: float | None, center: tuple[float, float] | None, half: float, name: str = ""
) -> MapFiles:
    """The tiles that overlap the square of half side ``half`` around the centre (default: the middle of
    the tiled area). ``name`` names the map in errors (default: ``path``)."""
    directory = open_tile_directory(path, grid_size)
    s = directory.grid_size
    if center is None:
        i_min, i_max, j_min, j_max = directory.bounds
        center = ((i_min + i_max + 1) * s / 2, (j_min + j_max + 1) * s / 2)
    x0, x1, y0, y1 = square(center, half)
    i0, i1, j0, j1 = tile_index(x0, s), tile_index(x1, s), tile_index(y0, s), tile_index(y1, s)
    keys = [decode_key(c) for c in directory.codes_in_box(i0, i1, j0, j1)]
    if not keys:
        i_min, i_max, j_min, j_max = directory.bounds
        raise UserError(
            f"no tiles of {name or path} around the search centre ({center[0]:g}, {center[1]:g}); the tiles span"
            f" x {i_min * s:g}..{(i_max + 1) * s:g} m, y {j_min * s:g}..{(j_max + 1) * s:g} m: move --center"
        )
    return MapFiles([directory.tile_path(key) for key in keys], center)


def url_tile_files(url: str, grid_size: float | None, center: tuple[float, float] | None, half: float) -> MapFiles:
    """The tiles of the map at ``url`` around the search, fetched into the map store's cache (the defaults of
    MapStoreConfig); the cached index of the revision in use picks them as a local index would."""
    store = MapStore(url)
    try:
        around = tile_files(store.dir, grid_size, center, half, name=store.url)
        stems = [f.name[: -len(".pcd")] for f in around.files]
        fetched = store.fetch(stems)
    finally:
        store.close()
    failed = [t.error for t in fetched if t.path is None]
    if failed:
        raise UserError(
            f"{len(failed)} of the {len(fetched)} tiles of {store.url} around the search could not be fetched,"
            f" e.g. {failed[0]}"
        )
    return MapFiles([t.path for t in fetched], around.center)


def block_files(path: Path, center: tuple[float, float] | None, half: float) -> MapFiles:
    """The blocks whose bounds overlap the square (default centre: the middle of all blocks)."""
    index = read_block_index(path)
    lo = np.array([b.bounds_min[:2] for b in index.blocks]).reshape(-1, 2)
    hi = np.array([b.bounds_max[:2] for b in index.blocks]).reshape(-1, 2)
    if len(lo) == 0:
        raise UserError(f"block directory {path} lists no blocks; rebuild it with `gpm blocks`")
    if center is None:
        center = tuple(float(v) for v in (lo.min(axis=0) + hi.max(axis=0)) / 2)
    x0, x1, y0, y1 = square(center, half)
    hit = (hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)
    if not hit.any():
        raise UserError(
            f"no block of {path} overlaps the search around ({center[0]:g}, {center[1]:g}); the blocks span"
            f" x {lo[:, 0].min():g}..{hi[:, 0].max():g} m, y {lo[:, 1].min():g}..{hi[:, 1].max():g} m: move --center"
        )
    return MapFiles([path / index.blocks[k].file for k in np.flatnonzero(hit)], center)


def map_files(args: argparse.Namespace, half: float) -> MapFiles:
    center = tuple(args.center) if args.center else None
    if is_map_store_url(args.map):
        return url_tile_files(args.map, args.grid_size, center, half)
    path = Path(args.map)
    if path.is_file():
        return MapFiles([path], center)
    if (path / BLOCK_INDEX).is_file():
        return block_files(path, center, half)
    if path.is_dir():
        return tile_files(path, args.grid_size, center, half)
    raise UserError(f"map {path} does not exist; give a tile directory, a PCD file or a block directory")


def run(args: argparse.Namespace) -> int:
    if not Path(args.scan).is_file():
        raise UserError(f"scan {args.scan} does not exist; give a PCD file of one scan in the base frame")
    if args.threads < 0:
        raise UserError(f"--threads must be >= 0 (got {args.threads}); 0 = all cores")
    program = find_program()
    defaults = program_defaults(program)
    size = defaults["size"] if args.size is None else args.size
    if not (math.isfinite(size) and size > 0):
        raise UserError(f"--size must be > 0 m (got {size})")
    if not (0 < args.yaw_range <= 360):
        raise UserError(f"--yaw-range must be in (0, 360] deg (got {args.yaw_range})")
    # The map must reach as far around the square as the scan does.
    found = map_files(args, size / 2 + defaults["max_range"])
    cmd = [str(program), "--scan", str(args.scan), "--size", repr(size), "--threads", str(args.threads)]
    cmd += ["--yaw-center", repr(math.radians(args.yaw_center)), "--yaw-range", repr(math.radians(args.yaw_range))]
    if found.center is not None:
        cmd += ["--center", repr(found.center[0]), repr(found.center[1])]
    for f in found.files:
        cmd += ["--map", str(f)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ)
    if proc.returncode == 2 or not proc.stdout.strip():
        raise UserError(proc.stderr.strip().replace(f"{PROGRAM}: error: ", "") or f"{PROGRAM} failed")
    answer = json.loads(proc.stdout)
    answer["tiles_loaded"] = len(found.files)
    print(json.dumps(answer), flush=True)
    if not answer["found"]:
        print(f"gpm global-localize: no acceptable pose: {answer['reason']}", file=sys.stderr)
        return 1
    return 0
