"""Writes the seed corpora of the fuzz targets into test/fuzz/seeds/<target>/ (committed; each file a few
hundred bytes): PCD files in every encoding and layout the readers accept (padding, float64, COUNT > 1,
organised clouds, NaN points), the first points of the real scans committed in test/data, tile indexes, and
PointCloud2 layouts. Usage: python3 test/fuzz/make_seeds.py"""

from __future__ import annotations

import json
import shutil
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np

from grid_puzzle_localization.pcd.reader import read_pcd
from grid_puzzle_localization.pcd.writer import write_pcd

SEEDS = Path(__file__).resolve().parent / "seeds"
REAL = Path(__file__).resolve().parents[1] / "data"
REAL_FILES = ("hdl32_pair/251370668.pcd", "isprs_terrain_utm/samp11-utm.pcd")
POINTS = 6  # per seed cloud: enough for every code path, small enough for the fuzzer to mutate


def clouds(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Point arrays of the layouts the readers meet in the wild."""
    xyz = rng.uniform(-50, 50, size=(POINTS, 3))

    def cloud(dtype) -> np.ndarray:
        out = np.zeros(POINTS, dtype=dtype)
        for k, name in enumerate("xyz"):
            out[name] = xyz[:, k]
        return out

    padded = cloud([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_", "u1", (4,)), ("intensity", "<f4")])
    with_nan = cloud([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    with_nan["y"][2] = np.nan
    return {
        "xyz": cloud([("x", "<f4"), ("y", "<f4"), ("z", "<f4")]),
        "padded": padded,
        "double": cloud([("intensity", "<u2"), ("z", "<f8"), ("y", "<f8"), ("x", "<f8")]),
        "nan": with_nan,
    }


def real_heads(out: Path) -> None:
    """The first POINTS points of each real file, in their own encoding and fields."""
    for name in REAL_FILES:
        if (REAL / name).is_file():
            cloud = read_pcd(REAL / name)
            write_pcd(out / f"real_{Path(name).stem}.pcd", cloud.points[:POINTS], cloud.header.data)


def pcd_seeds(out: Path) -> None:
    rng = np.random.default_rng(16)
    for name, points in clouds(rng).items():
        for encoding in ("ascii", "binary", "binary_compressed"):
            write_pcd(out / f"{name}_{encoding}.pcd", points, encoding)
    # An organised cloud (HEIGHT > 1) and a header-only empty tile, as the tiler writes for no points.
    text = (out / "xyz_ascii.pcd").read_text()
    organised = text.replace(f"WIDTH {POINTS}", f"WIDTH {POINTS // 2}").replace("HEIGHT 1", "HEIGHT 2")
    (out / "organised_ascii.pcd").write_text(organised)
    write_pcd(out / "empty_binary.pcd", clouds(rng)["xyz"][:0], "binary")
    real_heads(out)


def index_seeds(out: Path) -> None:
    """index.json of two tiles in the tiler's schema (tiling/index.py) and a minimal one."""
    tiles = [
        {
            "key": [i, j],
            "stem": f"{i * 2 + 1.0}_{j * 2 + 1.0}",
            "file": f"{i * 2 + 1.0}_{j * 2 + 1.0}.pcd",
            "center": [i * 2 + 1.0, j * 2 + 1.0],
            "points": 3,
            "bounds": {"min": [i * 2.0, j * 2.0, 0.0], "max": [i * 2 + 1.5, j * 2 + 1.5, 1.0]},
            "bytes": 236,
            "data_bytes": 36,
        }
        for i, j in ((0, 0), (-1, 3))
    ]
    fields = [{"name": n, "size": 4, "type": "F", "count": 1} for n in "xyz"]
    index = {
        "format": "grid_puzzle_tiles",
        "version": 1,
        "grid_size": 2.0,
        "origin": [0.0, 0.0],
        "fields": fields,
        "record_bytes": 12,
        "points": 6,
        "nonfinite_dropped": 0,
        "inputs": [{"path": "/map.pcd", "points": 6, "finite_points": 6, "data_bytes": 72}],
        "tiles": tiles,
    }
    (out / "index_two_tiles.json").write_text(json.dumps(index, indent=1))
    index["tiles"] = tiles[:1]
    (out / "index_compact.json").write_text(json.dumps(index, separators=(",", ":")))


def cloud_msg_seeds(out: Path) -> None:
    """Raw inputs of fuzz_point_cloud_msg (its harness decodes the layout from them): 36 floats followed by
    layout bytes, and zeros. libFuzzer derives other layouts from these."""
    xyz = np.arange(36, dtype="<f4").tobytes()
    (out / "data_36_floats.bin").write_bytes(xyz + struct.pack("<6B", 3, 3, 12, 36, 0, 3))
    (out / "data_empty.bin").write_bytes(b"\0" * 16)


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        for target, make in (
            ("pcd", pcd_seeds),
            ("tile_index", index_seeds),
            ("point_cloud_msg", cloud_msg_seeds),
        ):
            work = Path(tmp) / target
            work.mkdir()
            make(work)
            shutil.rmtree(SEEDS / target, ignore_errors=True)
            shutil.copytree(work, SEEDS / target)
    print(f"seeds written to {SEEDS}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
