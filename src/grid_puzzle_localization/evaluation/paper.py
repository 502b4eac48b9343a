"""The grid puzzle paper's published figures (Section IV), for side-by-side comparison. CPU in
percent of one core, memory in MB as the paper prints it (psutil), RMSE in metres."""

from __future__ import annotations

PAPER_FIGURES: dict[str, dict] = {
    "courtyard": {
        "n": 17,
        "k": 10,
        "grid_size_m": 2.0,
        "ndt_threads": 2,
        "duration_s": 1269,
        "trajectory_km": 0.646,
        "cpu_percent_mean": {"global": 74.79, "grid_puzzle": 56.06},
        "memory_mb_mean": {"global": 166.01, "grid_puzzle": 111.02},
        "memory_reduction_percent": -33.12,
        "rmse_between_modes_m": 0.0433,
        "global_map_mb": 631.1,
        "tile_files": 8282,
        "storage_overhead_bytes": 0,
    },
    "urban": {
        "n": 25,
        "k": 20,
        "grid_size_m": 2.0,
        "ndt_threads": 4,
        "duration_s": 785,
        "trajectory_km": 3.64,
        "cpu_percent_mean": {"global": 253.28, "grid_puzzle": 237.89},
        "memory_mb_mean": {"global": 509.38, "grid_puzzle": 193.12},
        "memory_reduction_percent": -62.09,
        "rmse_between_modes_m": 0.0677,
        "global_map_mb": 1267.4,
        "tile_files": 47480,
        "storage_overhead_bytes": 0,
    },
}
