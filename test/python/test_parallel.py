"""The forked background jobs: each runs exactly once, beside the caller, and a failure surfaces."""

import os

import pytest

from grid_puzzle_localization.tiling.parallel import in_background


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


def test_caller_failure_still_waits_for_the_child(tmp_path):
    def job() -> None:
        (tmp_path / "job").write_text("done")

    with pytest.raises(ValueError), in_background([job], fork=True):
        raise ValueError("index failed")
    assert (tmp_path / "job").read_text() == "done"  # the child had finished before the error surfaced
