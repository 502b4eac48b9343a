"""`make bench-scaling`: localizer memory and CPU as the map grows, global map against grid puzzle tiles.

The base map is the simulator's urban world (sim/worlds.py, full scale about 480 m x 710 m): its surfaces
sampled every ``--spacing`` metres. Maps of 1x, 4x and 16x its area repeat it on a 1x1, 2x2 and 4x4 grid.
For each size the C++ bench_scaling writes the global PCD and the tile files, then runs the same drive
through the core localizer (no roscore) twice, each in a fresh process: ``global`` (the map worker reads
the global PCD, as map_source pcd) and ``tiles`` (the paper's window of tile files read by reference, as
map_source tiles). One JSON line per size and mode, then one line with the ratios the targets are about.
A last line measures loading throughput: a 40 m x 40 m patch of the same world sampled densely
(``--dense-spacing``, thousands of points a 2 m tile, as in the paper's maps) read and folded into an
empty target by one thread, in points per second of wall time and per CPU second of that thread.
The drive heads 30 degrees north of east from 40 m inside the west edge, at 10 m/s, 10 Hz.
``--quick`` is a smoke run: a 80 m x 40 m crop of a fifth-scale world, 4 m tiles, a 2 s drive."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from hardware import cpu_model

from grid_puzzle_localization.pcd import write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.sim.worlds import make_world

FACTORS = (1, 4, 16)
DENSE_PATCH = 40.0  # [m] side of the loading-throughput patch


def surface_samples(triangles: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """About one point per ``spacing``^2 of surface, uniform on each triangle, as XYZ_DTYPE records."""
    a, b, c = (triangles[:, k].astype(np.float64) for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    counts = np.floor(area / spacing**2 + rng.random(len(area))).astype(np.int64)
    tri = np.repeat(np.arange(len(area)), counts)
    u, v = rng.random(len(tri)), rng.random(len(tri))
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    xyz = a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])
    out = np.empty(len(xyz), dtype=XYZ_DTYPE)
    for axis, name in enumerate("xyz"):
        out[name] = xyz[:, axis]
    return out


def crop(points: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    keep = (points["x"] >= x0) & (points["x"] < x1) & (points["y"] >= y0) & (points["y"] < y1)
    return points[keep]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: fifth-scale world, 1 m spacing, 2 s drive")
    parser.add_argument("--spacing", type=float, default=0.4, help="[m] surface sampling of the base map")
    parser.add_argument("--dense-spacing", type=float, default=0.05, help="[m] sampling of the throughput patch")
    parser.add_argument("--seconds", type=float, default=20.0, help="[s] drive length at 10 m/s")
    parser.add_argument("--grid-size", type=float, default=2.0, help="[m] tile side s")
    parser.add_argument("--n", type=int, default=25, help="window half side [tiles] (paper urban: 25)")
    parser.add_argument("--k", type=int, default=20, help="window extension toward the heading [tiles] (urban: 20)")
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh (the Makefile sources it)
    parser.add_argument("--exe", type=Path, default=workspace / "devel/lib/grid_puzzle_localization/bench_scaling")
    args = parser.parse_args()
    scale, spacing, seconds, n, k, s = 1.0, args.spacing, args.seconds, args.n, args.k, args.grid_size
    dense_spacing = args.dense_spacing
    if args.quick:
        scale, spacing, seconds, n, k, s, dense_spacing = 0.2, 0.35, 2.0, 8, 4, 4.0, 0.2
    hardware = {"cpu_model": cpu_model(), "cores": os.cpu_count(), "load_average_1min": os.getloadavg()[0]}
    world = make_world("urban", seed=1, scale=scale)
    x0, y0, x1, y1 = world.extent
    if args.quick:
        x0, y0, x1, y1 = x0, -20.0, x0 + 80.0, 20.0
    with tempfile.TemporaryDirectory(prefix="gpl_scaling_") as tmp:
        base = Path(tmp) / "base.pcd"
        rng = np.random.default_rng(1)
        write_pcd(base, crop(surface_samples(world.mesh.triangles, spacing, rng), x0, y0, x1, y1))
        # The throughput patch: where the drive starts (40 m inside the west edge, mid-height).
        px, py = x0 + 40.0, 0.5 * (y0 + y1)
        near = world.mesh.triangles
        centre = near.mean(axis=1)
        near = near[(np.abs(centre[:, 0] - px) < DENSE_PATCH) & (np.abs(centre[:, 1] - py) < DENSE_PATCH)]
        half = DENSE_PATCH / 2
        dense = crop(surface_samples(near, dense_spacing, rng), px - half, py - half, px + half, py + half)
        dense_pcd = Path(tmp) / "dense.pcd"
        write_pcd(dense_pcd, dense)
        del world, near, dense
        peaks: dict[tuple[int, str], float] = {}
        for factor in FACTORS:
            data = Path(tmp) / f"x{factor}"
            prepare = [str(args.exe), "prepare", str(base), str(factor), str(data), str(s), str(seconds)]
            subprocess.run(prepare, check=True)
            for mode in ("global", "tiles"):
                cmd = [str(args.exe), "run", str(data), mode, str(s), str(n), str(k), str(seconds)]
                result = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
                peaks[factor, mode] = result["peak_rss_mb"]
                area = round(factor * (x1 - x0) * (y1 - y0) / 1e6, 3)
                line = {"bench": "scaling", "factor": factor, "area_km2": area}
                line.update(result)
                line.update(grid_size_m=s, n=n, k=k, spacing_m=spacing, world_scale=scale, **hardware)
                print(json.dumps(line), flush=True)
            subprocess.run(["rm", "-rf", str(data)], check=True)
        data = Path(tmp) / "dense"
        subprocess.run([str(args.exe), "prepare", str(dense_pcd), "1", str(data), str(s), "0"], check=True)
        cmd = [str(args.exe), "load", str(data), str(s), "3"]
        result = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        print(json.dumps({"bench": "scaling_load", **result, "spacing_m": dense_spacing, **hardware}), flush=True)
        top = FACTORS[-1]
        print(
            json.dumps(
                {
                    "bench": "scaling_summary",
                    "tiles_peak_rss_16x_over_1x": round(peaks[top, "tiles"] / peaks[1, "tiles"], 3),
                    "tiles_over_global_peak_rss_16x": round(peaks[top, "tiles"] / peaks[top, "global"], 3),
                    "global_peak_rss_16x_over_1x": round(peaks[top, "global"] / peaks[1, "global"], 3),
                    "targets": {
                        "tiles_16x_over_1x_max": 1.1,
                        "tiles_over_global_16x_max": 0.1,
                        "load_mpoints_per_s_min": 2,
                    },
                }
            ),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
