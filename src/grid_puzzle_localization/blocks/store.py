"""The block directory shared by keyframe-stitched blocks and fixed-size submaps.

Layout (all coordinates in the map frame, metres)::

    block_0000.pcd ...   one binary PCD per block, fields x y z (float32)
    centroids.txt        one line per block: ``id cx cy cz``
    index.yaml           format, kind, build parameters, map_points, and per block: id, file,
                         points, bytes (file size), centroid, bounds {min, max} and kind-specific keys

The directory is written under a temporary name beside the target and renamed into place, so no
reader ever sees a partly written directory, and a failed write leaves the old one untouched.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array, xyz_records
from grid_puzzle_localization.util.atomic import atomic_directory, check_output_dir

FORMAT = "gpm_block_map"
VERSION = 1
INDEX_FILE = "index.yaml"
CENTROIDS_FILE = "centroids.txt"


@dataclass(frozen=True)
class BlockEntry:
    id: int
    file: str
    points: int
    bytes: int
    centroid: tuple[float, float, float]
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class BlockIndex:
    directory: Path
    kind: str  # "keyframe_blocks" or "fixed_submaps"
    params: dict[str, Any]
    map_points: int  # points of the map the blocks were made from (before any overlap)
    blocks: list[BlockEntry]

    def centroids(self) -> np.ndarray:
        """``(C, 3)`` centroids [m], row ``k`` for ``blocks[k]``."""
        return np.array([b.centroid for b in self.blocks], dtype=np.float64).reshape(-1, 3)

    def load_points(self, position: int) -> np.ndarray:
        """Points ``(N, 3)`` float64 [m] of ``blocks[position]``."""
        return xyz_array(read_pcd(self.directory / self.blocks[position].file).points)


def write_block_dir(
    target: str | os.PathLike,
    blocks: Iterable[tuple[np.ndarray, np.ndarray, dict[str, Any]]],
    kind: str,
    params: dict[str, Any],
    map_points: int,
    force: bool = False,
) -> BlockIndex:
    """Writes blocks ``(points (N, 3) [m], centroid (3,) [m], extra index keys)`` in the given order as
    ``block_0000.pcd`` ... with their index; blocks are consumed one at a time."""
    target = Path(target)
    check_output_dir(target, force)
    entries: list[BlockEntry] = []
    with atomic_directory(target) as tmp:
        for number, (points, centroid, extra) in enumerate(blocks):
            name = f"block_{number:04d}.pcd"
            record = xyz_records(np.asarray(points, dtype=np.float64).reshape(-1, 3))
            write_pcd(tmp / name, record, encoding="binary")
            stored = np.stack([record["x"], record["y"], record["z"]], axis=1).astype(np.float64)
            entries.append(
                BlockEntry(
                    id=number,
                    file=name,
                    points=len(record),
                    bytes=(tmp / name).stat().st_size,
                    centroid=tuple(float(v) for v in centroid),
                    bounds_min=tuple(float(v) for v in stored.min(axis=0)) if len(stored) else (0.0, 0.0, 0.0),
                    bounds_max=tuple(float(v) for v in stored.max(axis=0)) if len(stored) else (0.0, 0.0, 0.0),
                    extra=dict(extra),
                )
            )
        index = BlockIndex(target, kind, dict(params), int(map_points), entries)
        _write_text(tmp / CENTROIDS_FILE, _centroids_text(entries))
        _write_text(tmp / INDEX_FILE, yaml.safe_dump(_index_dict(index), sort_keys=False))
    return index


def _write_text(path: Path, text: str) -> None:
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def _centroids_text(entries: list[BlockEntry]) -> str:
    lines = ["# id cx cy cz  (block centroids, map frame, metres)"]
    lines += [f"{e.id} {e.centroid[0]!r} {e.centroid[1]!r} {e.centroid[2]!r}" for e in entries]
    return "\n".join(lines) + "\n"


def _index_dict(index: BlockIndex) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "kind": index.kind,
        "frame": "map",
        "params": index.params,
        "map_points": index.map_points,
        "blocks": [
            {
                "id": e.id,
                "file": e.file,
                "points": e.points,
                "bytes": e.bytes,
                "centroid": list(e.centroid),
                "bounds": {"min": list(e.bounds_min), "max": list(e.bounds_max)},
                **e.extra,
            }
            for e in index.blocks
        ],
    }


def read_block_index(directory: str | os.PathLike) -> BlockIndex:
    """Reads ``index.yaml`` of a block directory; raises UserError naming the file on bad content."""
    directory = Path(directory)
    path = directory / INDEX_FILE
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except OSError as err:
        raise UserError(f"cannot read block index {path}: {err.strerror}; build it with `gpm blocks`") from err
    except yaml.YAMLError as err:
        raise UserError(f"block index {path} is not valid YAML ({err}); rebuild it with `gpm blocks`") from err
    if not isinstance(data, dict) or data.get("format") != FORMAT or data.get("version") != VERSION:
        raise UserError(f"{path} is not a {FORMAT} version {VERSION} index; rebuild it with `gpm blocks`")
    known = {"id", "file", "points", "bytes", "centroid", "bounds"}
    try:
        blocks = [
            BlockEntry(
                id=int(b["id"]),
                file=str(b["file"]),
                points=int(b["points"]),
                bytes=int(b["bytes"]),
                centroid=tuple(float(v) for v in b["centroid"]),
                bounds_min=tuple(float(v) for v in b["bounds"]["min"]),
                bounds_max=tuple(float(v) for v in b["bounds"]["max"]),
                extra={k: v for k, v in b.items() if k not in known},
            )
            for b in data["blocks"]
        ]
    except (KeyError, TypeError, ValueError) as err:
        raise UserError(f"block index {path} has a malformed block entry ({err!r}); rebuild it") from err
    return BlockIndex(directory, str(data["kind"]), dict(data.get("params") or {}), int(data["map_points"]), blocks)
