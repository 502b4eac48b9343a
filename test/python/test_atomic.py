"""Atomic directories: published complete or not at all; with ``durable`` the contents are flushed to
disk before the rename that publishes them, and the rename itself after it."""

import pytest

from grid_puzzle_localization.util import atomic
from grid_puzzle_localization.util.atomic import atomic_directory, sync_filesystem


def test_durable_directory_is_flushed_before_it_is_published(tmp_path, monkeypatch):
    target = tmp_path / "tiles"
    events = []
    monkeypatch.setattr(atomic, "sync_filesystem", lambda path: events.append(("sync", target.exists())))
    monkeypatch.setattr(atomic, "fsync_path", lambda path: events.append(("fsync", path, target.exists())))
    with atomic_directory(target, durable=True) as tmp:
        (tmp / "a.pcd").write_text("tile")
    assert events == [("sync", False), ("fsync", tmp_path.resolve(), True)]
    assert (target / "a.pcd").read_text() == "tile"


def test_plain_directory_is_not_flushed(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic, "sync_filesystem", lambda path: pytest.fail("flushed"))
    with atomic_directory(tmp_path / "out") as tmp:
        (tmp / "f").write_text("x")
    assert (tmp_path / "out" / "f").read_text() == "x"


def test_syncfs_runs_on_a_real_file_system(tmp_path):
    (tmp_path / "f").write_text("x")
    sync_filesystem(tmp_path)  # raises OSError if the system call fails
    with pytest.raises(FileNotFoundError):
        sync_filesystem(tmp_path / "missing")
