"""Faults while `gpm tile` and `gpm simulate` write: the disk fills up (a size-limited tmpfs mounted for the
test; skipped when mounting is not permitted) and SIGINT arrives. Each must end with a clear one-line error,
leave no partial output directory (nor staging directory) behind, and keep the previous output intact."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fault_report import record

from grid_puzzle_localization.pcd.writer import write_pcd

GPM = "import sys; from grid_puzzle_localization.cli import main; sys.exit(main())"


def gpm(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", GPM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs
    )


def finished(proc: subprocess.Popen, timeout: float = 300) -> tuple[int, str]:
    _, err = proc.communicate(timeout=timeout)
    return proc.returncode, err


def snapshot(directory: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file below ``directory``."""
    return {
        str(p.relative_to(directory)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(directory.rglob("*"))
        if p.is_file()
    }


def random_map(path: Path, points: int, extent: float, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    cloud = np.zeros(points, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    for name, high in (("x", extent), ("y", extent), ("z", 5.0), ("intensity", 255.0)):
        cloud[name] = rng.uniform(0.0, high, points)
    write_pcd(path, cloud)
    return path


@pytest.fixture
def small_disk(tmp_path):
    """A tmpfs of 2 MiB: far less than the big map's tiles need."""
    mount = tmp_path / "small_disk"
    mount.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a size-limited tmpfs needs root")
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mount)], capture_output=True, text=True
    )
    if done.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here: {done.stderr.strip()}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=True)


def check_clean_failure(err: str, rc: int) -> None:
    """A non-zero exit whose last line is gpm's one-line error naming the cause (a forked tile writer's, with
    --jobs 2, among them); a short error, no traceback."""
    lines = err.strip().splitlines()
    assert rc != 0
    assert "Traceback" not in err, err
    assert len(lines) <= 3, err
    assert lines[-1].startswith("gpm ") and "no space left" in lines[-1].lower(), err


@pytest.mark.parametrize("grid_size", ["10", "1"])
def test_disk_full_during_tile_keeps_previous_output(small_disk, tmp_path, grid_size):
    """s = 10 m: 100 tiles, written by the tiler's process; s = 1 m: 10^4 tiles, by forked writers."""
    out = small_disk / "tiles"
    small = random_map(tmp_path / "small.pcd", 2_000, 20.0, seed=1)
    big = random_map(tmp_path / "big.pcd", 200_000, 100.0, seed=2)  # 3.2 MB of records
    rc, err = finished(gpm("tile", "--grid-size", "10", str(small), "-o", str(out)))
    assert rc == 0, err
    before = snapshot(out)
    start = time.monotonic()
    rc, err = finished(gpm("tile", "--grid-size", grid_size, "--jobs", "2", str(big), "-o", str(out), "--force"))
    seconds = time.monotonic() - start
    check_clean_failure(err, rc)
    assert snapshot(out) == before
    assert [p.name for p in small_disk.iterdir()] == ["tiles"], "staging directory left behind"
    record(f"disk full during gpm tile -s {grid_size}", f"exit {rc}: {err.strip()}", round(seconds, 2))


def test_disk_full_during_simulate_keeps_previous_output(small_disk):
    out = small_disk / "scenario"
    out.mkdir()
    (out / "scenario.yaml").write_text("previous output\n")
    before = snapshot(out)
    args = ["simulate", "courtyard", "--scale", "0.25", "--duration", "2", "--seed", "7", "--map-density", "0.2"]
    start = time.monotonic()
    rc, err = finished(gpm(*args, "-o", str(out), "--force", "--quiet"))
    seconds = time.monotonic() - start
    check_clean_failure(err, rc)
    assert snapshot(out) == before
    assert [p.name for p in small_disk.iterdir()] == ["scenario"], "staging directory left behind"
    record("disk full during gpm simulate", f"exit {rc}: {err.strip()}", round(seconds, 2))


def sigint_default() -> None:
    """In a child before exec: SIGINT unblocked and at its default disposition."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def writing_tiles(parent: Path, name: str) -> bool:
    """Whether a tile file is in the tiler's staging directory for output ``name`` yet (stops at the first one
    found: listing a directory of thousands of files each poll would let a fast tiler finish unseen)."""
    for staging in parent.glob(f".{name}.tmp-*"):
        try:
            with os.scandir(staging) as entries:
                if any(e.name.endswith(".pcd") for e in entries):
                    return True
        except FileNotFoundError:  # moved into place or removed meanwhile
            continue
    return False


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_sigint_during_tile_leaves_no_partial_output(tmp_path, jobs):
    """SIGINT once the tiler writes tile files (into its staging directory), in the single-process tiler
    and with forked tile writers (160,000 tiles: enough that a busy machine's poll sees the writing)."""
    big = random_map(tmp_path / "big.pcd", 2_000_000, 400.0, seed=3)
    previous = tmp_path / "previous"
    rc, err = finished(
        gpm("tile", "--grid-size", "50", str(random_map(tmp_path / "s.pcd", 500, 20.0, 4)), "-o", str(previous))
    )
    assert rc == 0, err
    before = snapshot(previous)
    for target, force in ((tmp_path / "fresh", []), (previous, ["--force"])):
        # SIGINT as a terminal delivers it, whatever this process inherited or was left with (ignored, or blocked):
        # the full suite, run in CI, saw the tiler exit 0 where this test alone passes.
        proc = gpm(
            "tile",
            "--grid-size",
            "1",
            "--jobs",
            jobs,
            "--no-progress",
            str(big),
            "-o",
            str(target),
            *force,
            preexec_fn=sigint_default,
        )
        deadline = time.monotonic() + 120
        while not writing_tiles(tmp_path, target.name) and proc.poll() is None:
            assert time.monotonic() < deadline, "the tiler never started writing"
            time.sleep(0.01)
        interrupted = time.monotonic()
        proc.send_signal(signal.SIGINT)
        rc, err = finished(proc)
        seconds = time.monotonic() - interrupted
        assert rc == 130, err
        assert "interrupted; no partial output was kept" in err
        assert "Traceback" not in err, err
        assert not (tmp_path / "fresh").exists()
        assert snapshot(previous) == before
        assert sorted(p.name for p in tmp_path.iterdir()) == ["big.pcd", "previous", "s.pcd"]
        record(
            f"SIGINT during gpm tile --jobs {jobs} ({'replacing' if force else 'new'} output)",
            f"exit {rc}",
            round(seconds, 2),
        )
