"""The forked tile-writer split: every item handled exactly once, failures surface."""

import os

import pytest

from grid_puzzle_localization.tiling.parallel import MIN_ITEMS_TO_FORK, run_split


@pytest.mark.parametrize("n", [0, 5, MIN_ITEMS_TO_FORK, MIN_ITEMS_TO_FORK + 1])
def test_every_item_once_across_processes(tmp_path, n):
    def work(share: range) -> None:
        for k in share:  # O_EXCL: a second writer of the same item would fail
            os.close(os.open(tmp_path / f"{k}.{os.getpid()}", os.O_CREAT | os.O_EXCL | os.O_WRONLY))

    run_split(n, work, processes=2)
    names = [p.name.split(".") for p in tmp_path.iterdir()]
    assert sorted(int(k) for k, _ in names) == list(range(n))
    assert len({pid for _, pid in names}) == (2 if n >= MIN_ITEMS_TO_FORK else min(n, 1))


def test_child_failure_raises_after_parent_work(tmp_path):
    done = []

    def work(share: range) -> None:
        if share.start == 1:
            raise RuntimeError("disk full")
        done.append(len(share))

    with pytest.raises(OSError, match="1 tile writer process"):
        run_split(MIN_ITEMS_TO_FORK, work, processes=2)
    assert done == [MIN_ITEMS_TO_FORK // 2]
