"""The input file of the C++ bench_localizer (its format is documented in bench_localizer.cpp), written by the
benchmarks that run it (they run with bench/ on sys.path)."""

from __future__ import annotations

from typing import BinaryIO

import numpy as np


def write_header(f: BinaryIO, rate_hz: float, cloud: np.ndarray, mount: np.ndarray, gyro: np.ndarray) -> None:
    """The scan rate [Hz], the map (N x 3 float32, map frame), base_T_sensor (4 x 4) and the gyro samples (rows of
    stamp and x, y, z in base_link [rad/s]); the scans follow, after write_scan_count."""
    f.write(b"GPLBENCH" + np.float64(rate_hz).tobytes())
    f.write(np.uint64(len(cloud)).tobytes() + np.ascontiguousarray(cloud, dtype=np.float32).tobytes())
    f.write(np.asarray(mount, dtype=np.float64).tobytes())
    samples = np.asarray(gyro, dtype=np.float64).reshape(-1, 4)
    f.write(np.uint64(len(samples)).tobytes() + samples.tobytes())


def write_scan_count(f: BinaryIO, count: int) -> None:
    f.write(np.uint64(count).tobytes())


def write_scan(f: BinaryIO, stamp: float, truth: np.ndarray, points: np.ndarray, times: np.ndarray) -> None:
    """One scan: its stamp [s], the true map_T_base (4 x 4), its points (N x 3 float32, sensor frame) and their
    capture times after the stamp [s] (empty for an instantaneous scan)."""
    f.write(np.float64(stamp).tobytes() + np.asarray(truth, dtype=np.float64).tobytes())
    f.write(np.uint64(len(points)).tobytes() + np.ascontiguousarray(points, dtype=np.float32).tobytes())
    f.write(np.uint64(len(times)).tobytes() + np.ascontiguousarray(times, dtype=np.float32).tobytes())
