#!/usr/bin/env python3
"""Benchmark of `gpm simulate`: prints one JSON object.

- rays_per_s: Embree ray casting of HDL-32E-like sweeps in the full-scale urban world (median of repeats);
- sweep_rays_per_s: the same including per-ray poses, noise and point packing;
- per sensor, on its full-scale default world: seconds of wall time per simulated second of the
  localization run (sweeps + IMU + bag writing), and prior-map points accumulated per second of the
  mapping run, plus the final map size;
- peak RSS of this process and hardware info (CPU model, cores, threads used).
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

from grid_puzzle_localization.malloc_tuning import reuse_large_buffers
from grid_puzzle_localization.sim import worlds
from grid_puzzle_localization.sim.lidar import Mount, SweepSimulator
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.scenario import MOUNTS, ScenarioConfig, _rng, generate
from grid_puzzle_localization.sim.sensors import SENSORS
from grid_puzzle_localization.sim.trajectory import localization_trajectory


def _cpu_model() -> str:
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor()


def _raycast(threads: int, repeats: int, sweeps: int) -> dict:
    world = worlds.make_world("urban", 0, 1.0)
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
            rng = np.random.default_rng(0)
            start = time.perf_counter()
            for k in range(sweeps):
                sim.simulate(traj, 100.0 + k / sensor.rate, sensor.sweep(k), rng)
            sweep_rates.append(sweeps * sensor.rays_per_sweep / (time.perf_counter() - start))
    return {
        "rays_per_s": round(statistics.median(cast_rates)),
        "sweep_rays_per_s": round(statistics.median(sweep_rates)),
        "urban_triangles": len(world.mesh.faces),
    }


def _scenario(world: str, duration: float, threads: int) -> dict:
    cfg = ScenarioConfig(world=world, duration=duration, threads=threads)
    with tempfile.TemporaryDirectory(dir=os.environ.get("TMPDIR", "/tmp")) as tmp:
        s = generate(cfg, Path(tmp) / world, progress=False)
        sizes = {p.name: p.stat().st_size for p in s.directory.iterdir()}
    return {
        "sensor": cfg.resolved().sensor,
        "simulated_s": round(s.duration, 3),
        "seconds_per_simulated_second": round(s.seconds_localization / s.duration, 3),
        "localization_rays_per_s": round(s.rays / s.seconds_localization),
        "mapping_run_s": round(s.map_sweeps / 10.0, 1),
        "map_input_points_per_s": round(s.map_points_in / s.seconds_mapping),
        "map_points": s.map_points,
        "bag_mb_per_simulated_s": round(sizes["scenario.bag"] / 1e6 / s.duration, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated seconds per scenario")
    args = parser.parse_args()
    reuse_large_buffers()  # as `gpm simulate` does
    out = {"threads": args.threads, "repeats": args.repeats}
    out.update(_raycast(args.threads, args.repeats, sweeps=30))
    out["courtyard_livox"] = _scenario("courtyard", args.duration, args.threads)
    out["urban_hdl32"] = _scenario("urban", args.duration, args.threads)
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    out["hardware"] = {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),  # the CPU may be shared
        "python": platform.python_version(),
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
