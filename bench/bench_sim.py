#!/usr/bin/env python3
"""Benchmark of `gpm simulate`: prints one JSON object per line (ray casting, then one per scenario).

- rays_per_s: Embree ray casting of HDL-32E-like sweeps in the full-scale urban world (median of repeats);
- sweep_rays_per_s: the same including per-ray poses, noise and point packing, one sweep per thread
  as `gpm simulate` runs them;
- per sensor, on its full-scale default world, end to end: seconds of wall time per simulated second of
  the localization run and its rays per second (sweeps, movers, IMU, bag writing), the mapping run's rays
  per second, both together (generation_rays_per_s), rays per CPU-second of the process (all threads;
  meaningful on a shared machine) and prior-map points accumulated per second, plus the final map size;
- peak RSS of this process and hardware info (CPU model, cores, threads used) on every line.

--quick: a few seconds on small worlds (scale 0.2, 1 s, one repeat), to check that the benchmark runs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from hardware import cpu_model

from grid_puzzle_localization.sim import worlds
from grid_puzzle_localization.sim.lidar import Mount, SweepSimulator
from grid_puzzle_localization.sim.ordered import ordered_map
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.scenario import MOUNTS, ScenarioConfig, _rng, generate
from grid_puzzle_localization.sim.sensors import SENSORS
from grid_puzzle_localization.sim.trajectory import localization_trajectory
from grid_puzzle_localization.util.malloc_tuning import reuse_large_buffers


def _raycast(threads: int, repeats: int, sweeps: int, scale: float) -> dict:
    world = worlds.make_world("urban", 0, scale)
    traj = localization_trajectory(world, 1.0, _rng(0, 1))
    sensor = SENSORS["hdl32"]
    cast_rates, sweep_rates = [], []
    with RayCaster(world.mesh, threads) as caster:
        sim = SweepSimulator(world.mesh, caster, sensor, Mount(np.array(MOUNTS["urban"]), np.eye(3)))
        rays = [
            sim.rays(traj, 100.0 + k / sensor.rate + sensor.sweep(k).dt, sensor.sweep(k).directions)
            for k in range(sweeps)
        ]
        for _ in range(repeats):
            start = time.perf_counter()
            for origin, direction in rays:
                caster.cast(origin, direction)
            cast_rates.append(sweeps * sensor.rays_per_sweep / (time.perf_counter() - start))
    with RayCaster(world.mesh, threads=1) as caster:  # as in `gpm simulate`: one sweep per worker thread
        sim = SweepSimulator(world.mesh, caster, sensor, Mount(np.array(MOUNTS["urban"]), np.eye(3)))

        def one(k: int) -> np.ndarray:
            return sim.simulate(traj, 100.0 + k / sensor.rate, sensor.sweep(k), np.random.default_rng(k))

        for _ in range(repeats):
            start = time.perf_counter()
            for _ in ordered_map(one, sweeps, threads):
                pass
            sweep_rates.append(sweeps * sensor.rays_per_sweep / (time.perf_counter() - start))
    return {
        "bench": "sim_raycast",
        "world": "urban",
        "scale": scale,
        "rays_per_s": round(statistics.median(cast_rates)),
        "sweep_rays_per_s": round(statistics.median(sweep_rates)),
        "urban_triangles": len(world.mesh.faces),
    }


def _scenario(world: str, duration: float, threads: int, repeats: int, scale: float) -> dict:
    """End-to-end `gpm simulate` figures, each the median over ``repeats`` runs (the output is identical)."""
    cfg = ScenarioConfig(world=world, duration=duration, threads=threads, scale=scale)
    runs = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(dir=os.environ.get("TMPDIR", "/tmp")) as tmp:
            s = generate(cfg, Path(tmp) / world, progress=False)
            sizes = {p.name: p.stat().st_size for p in s.directory.iterdir()}
        runs.append(s)

    def median(f) -> float:
        return statistics.median(f(s) for s in runs)

    s = runs[0]
    return {
        "bench": "sim_scenario",
        "world": world,
        "scale": scale,
        "sensor": cfg.resolved().sensor,
        "simulated_s": round(s.duration, 3),
        "seconds_per_simulated_second": round(median(lambda r: r.seconds_localization / r.duration), 3),
        "localization_rays_per_s": round(median(lambda r: r.rays / r.seconds_localization)),
        "mapping_rays_per_s": round(median(lambda r: r.map_rays / r.seconds_mapping)),
        "generation_rays_per_s": round(
            median(lambda r: (r.rays + r.map_rays) / (r.seconds_localization + r.seconds_mapping))
        ),
        "localization_rays_per_cpu_s": round(median(lambda r: r.rays / r.cpu_seconds_localization)),
        "mapping_rays_per_cpu_s": round(median(lambda r: r.map_rays / r.cpu_seconds_mapping)),
        "mapping_run_s": round(s.map_sweeps / 10.0, 1),
        "map_input_points_per_s": round(median(lambda r: r.map_points_in / r.seconds_mapping)),
        "map_points": s.map_points,
        "bag_mb_per_simulated_s": round(sizes["scenario.bag"] / 1e6 / s.duration, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated seconds per scenario")
    parser.add_argument("--quick", action="store_true", help="small worlds, 1 s, one repeat: checks that it runs")
    args = parser.parse_args()
    scale, sweeps = 1.0, 30
    if args.quick:
        scale, sweeps, args.repeats, args.duration = 0.2, 2, 1, 1.0
    reuse_large_buffers()  # as `gpm simulate` does
    rows = [_raycast(args.threads, args.repeats, sweeps, scale)]
    rows.append(_scenario("courtyard", args.duration, args.threads, args.repeats, scale))
    rows.append(_scenario("urban", args.duration, args.threads, args.repeats, scale))
    machine = {
        "threads": args.threads,
        "repeats": args.repeats,
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),  # the CPU may be shared
        "python": platform.python_version(),
    }
    for row in rows:
        print(json.dumps({**row, **machine}), flush=True)


if __name__ == "__main__":
    main()
