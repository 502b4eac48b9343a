"""ordered_map: results in index order whatever the thread timing, bounded look-ahead, errors surface."""

import contextlib
import threading
import time

import pytest

from grid_puzzle_localization.sim.ordered import ordered_map


@pytest.mark.parametrize("threads", [1, 2, 4])
def test_results_come_back_in_index_order(threads):
    def slow_for_even(k: int) -> int:
        time.sleep(0.002 if k % 2 == 0 else 0.0)  # later calls often finish first
        return k * k

    assert list(ordered_map(slow_for_even, 40, threads)) == [k * k for k in range(40)]


def test_look_ahead_is_bounded_and_abandoning_cancels_queued_calls():
    started, lock = [], threading.Lock()

    def record(k: int) -> int:
        with lock:
            started.append(k)
        return k

    with contextlib.closing(ordered_map(record, 1000, threads=2, ahead=2)) as results:
        assert next(results) == 0
        time.sleep(0.05)
        assert len(started) <= 2 * 2 + 1  # the consumed one plus at most ahead * threads queued
    time.sleep(0.05)
    assert len(started) <= 2 * 2 + 1  # nothing new ran after the consumer stopped


def test_an_error_in_a_call_reaches_the_consumer():
    def fail_at_three(k: int) -> int:
        if k == 3:
            raise ValueError("sweep 3 failed")
        return k

    got = []
    with pytest.raises(ValueError, match="sweep 3 failed"):
        for value in ordered_map(fail_at_three, 10, threads=2):
            got.append(value)
    assert got == [0, 1, 2]
