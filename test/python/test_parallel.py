"""The forked background jobs (each runs exactly once, beside the caller, and a failure surfaces) and the
thread pool that groups chunks ahead (results in order, bounded work in flight)."""

import errno
import functools
import json
import os
import threading
import time

import pytest

from grid_puzzle_localization.tiling import parallel
from grid_puzzle_localization.tiling.parallel import SharedBatches, in_background, map_ahead


@pytest.mark.parametrize("fork", [True, False])
def test_job_runs_once_beside_the_caller(tmp_path, fork):
    def job() -> None:
        (tmp_path / f"job.{os.getpid()}").write_text("done")

    with in_background([job], fork):
        (tmp_path / f"caller.{os.getpid()}").write_text("done")
    names = sorted(p.name.split(".")[0] for p in tmp_path.iterdir())
    pids = {p.name.split(".")[1] for p in tmp_path.iterdir()}
    assert names == ["caller", "job"]
    assert len(pids) == (2 if fork else 1)


def test_failed_child_raises_after_the_block(tmp_path):
    def job() -> None:
        raise RuntimeError("disk full")

    with pytest.raises(OSError, match="tile writer process failed"), in_background([job], fork=True):
        (tmp_path / "caller").write_text("done")
    assert (tmp_path / "caller").exists()


@pytest.mark.parametrize("while_waiting", [None, lambda: time.sleep(0.001)])
def test_a_child_os_error_is_named_in_the_parent_error(while_waiting):
    """A child that runs out of disk while the parent has nothing more to write: the parent's own error (the one
    line gpm prints last) says why, not only that a child failed."""

    def job() -> None:
        raise OSError(errno.ENOSPC, "No space left on device", "/mnt/small/3.5_63.5.pcd")

    reason = r"tile writer process failed: \[Errno 28\] No space left on device: '/mnt/small"
    with pytest.raises(OSError, match=reason), in_background([job], fork=True, while_waiting=while_waiting):
        pass


def test_caller_failure_stops_and_waits_for_the_child(tmp_path):
    """The caller's output is discarded when it fails, so its child is stopped, and it is waited for: no
    child outlives the block, and one that would have run for a minute leaves no result."""

    def job() -> None:
        # Written whole, then renamed: the caller polls for the name and must never read an empty file.
        (tmp_path / "pid.tmp").write_text(str(os.getpid()))
        os.replace(tmp_path / "pid.tmp", tmp_path / "pid")
        time.sleep(60)
        (tmp_path / "job").write_text("done")

    with pytest.raises(ValueError), in_background([job], fork=True):
        while not (tmp_path / "pid").exists():
            time.sleep(0.01)
        raise ValueError("index failed")
    with pytest.raises(ProcessLookupError):
        os.kill(int((tmp_path / "pid").read_text()), 0)  # waited for (reaped), not a zombie
    assert not (tmp_path / "job").exists()


def test_two_jobs_run_in_two_children(tmp_path):
    def job(name: str):
        return lambda: (tmp_path / f"{name}.{os.getpid()}").write_text("done")

    with in_background([job("a"), job("b")], fork=True):
        pass
    pids = {p.name.split(".")[1] for p in tmp_path.iterdir()}
    assert sorted(p.name.split(".")[0] for p in tmp_path.iterdir()) == ["a", "b"]
    assert len(pids) == 2 and str(os.getpid()) not in pids


def test_while_waiting_is_called_until_the_children_exit(tmp_path):
    def job() -> None:  # finishes only after the caller's while_waiting has run once
        while not (tmp_path / "go").exists():
            time.sleep(0.001)
        (tmp_path / "job").write_text("done")

    finished_at_call = []

    def while_waiting() -> None:
        finished_at_call.append((tmp_path / "job").exists())
        (tmp_path / "go").touch()

    with in_background([job], fork=True, while_waiting=while_waiting):
        pass
    assert finished_at_call[0] is False  # called while the child was still running
    assert (tmp_path / "job").read_text() == "done"


def test_while_waiting_does_not_hide_a_failed_child(tmp_path):
    def job() -> None:
        raise RuntimeError("disk full")

    def pause() -> None:
        time.sleep(0.001)

    with pytest.raises(OSError, match="tile writer process failed"), in_background([job], True, pause):
        pass


def test_map_ahead_keeps_order_and_bounds_the_work_in_flight():
    lock = threading.Lock()
    running, most = 0, 0
    taken = []

    def items():
        for k in range(40):
            taken.append(k)
            yield k

    def slow_square(k: int) -> int:
        nonlocal running, most
        with lock:
            running += 1
            most = max(most, running)
        time.sleep(0.002 * (k % 3))  # later items finish first now and then
        with lock:
            running -= 1
        return k * k

    for k, result in enumerate(map_ahead(slow_square, items(), threads=2)):
        assert result == k * k
        assert len(taken) <= k + 2  # items are read at most `threads` ahead of the consumer
    assert most <= 2


def test_map_ahead_raises_the_job_error():
    def fail_on_three(k: int) -> int:
        if k == 3:
            raise ValueError("bad chunk 3")
        return k

    with pytest.raises(ValueError, match="bad chunk 3"):
        list(map_ahead(fail_on_three, range(10), threads=2))


def test_waiting_ends_when_the_children_exit_not_after_the_pause(monkeypatch):
    monkeypatch.setattr(parallel, "WAIT_PAUSE_S", 60.0)  # were the pause not cut short, this would take a minute
    calls = []

    def job() -> None:
        time.sleep(0.2)

    start = time.monotonic()
    with in_background([job], fork=True, while_waiting=lambda: calls.append(1)):
        pass
    assert time.monotonic() - start < 30.0
    assert calls  # the child was still running when the block ended


@pytest.mark.parametrize("total", [0, 1, 63, 64, 65, 1000, 100_003])
def test_shared_batches_hand_every_item_to_exactly_one_of_several_processes(tmp_path, total):
    with SharedBatches(total) as batches:

        def job(name: str) -> None:
            taken = [(which.start, which.stop) for which in batches]
            (tmp_path / name).write_text(json.dumps(taken))

        with in_background([functools.partial(job, "a"), functools.partial(job, "b")], fork=True):
            job("caller")
    taken = [pair for name in ("a", "b", "caller") for pair in json.loads((tmp_path / name).read_text())]
    items = sorted(k for start, stop in taken for k in range(start, stop))
    assert items == list(range(total))  # each exactly once
    assert len(taken) <= 512  # the whole queue fits one atomic pipe write
    assert all(stop - start == batches.size for start, stop in taken if stop != total)
