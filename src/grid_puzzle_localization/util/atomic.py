"""Atomic writes: a temporary file (or directory) beside the destination, then os.replace, so a
reader never sees a half-written file and a failure or interrupt leaves the old content in place.

Output directories of the gpm commands follow one rule (:func:`check_output_dir`): an existing
non-empty directory is replaced only with ``--force``, at commit time."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from grid_puzzle_localization.errors import UserError

# mkstemp creates files readable by the owner only; written files get the usual umask-based mode.
_UMASK = os.umask(0)
os.umask(_UMASK)


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", fsync: bool = True, **open_kwargs) -> Iterator[IO]:
    """Opens a temporary file beside ``path``; on a clean exit it replaces ``path``, on an exception
    it is removed, so ``path`` is never half-written. ``fsync=False`` skips the flush to disk for bulk
    writes whose directory is itself published atomically (see atomic_directory)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **open_kwargs) as f:
            yield f
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_directory(target: str | os.PathLike, durable: bool = False) -> Iterator[Path]:
    """Yields an empty temporary directory beside ``target``; on a clean exit it replaces ``target``
    (an existing one is moved aside first, then deleted), on an exception it is removed. Callers check
    beforehand whether replacing an existing ``target`` is allowed. ``durable`` flushes the contents
    to disk before the rename that publishes them and the rename after it (one syncfs, not one fsync
    per file), so even a power loss leaves the old ``target`` or the complete new one."""
    target = Path(target)
    parent = target.resolve().parent
    tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.tmp-"))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_UMASK)  # mkdtemp makes it private
        if durable:
            sync_filesystem(tmp)
        if target.exists():
            old = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.old-"))
            os.replace(target, old / target.name)
            os.replace(tmp, target)
            shutil.rmtree(old)
        else:
            os.replace(tmp, target)
        if durable:
            fsync_path(parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def check_output_dir(out_dir: str | os.PathLike, force: bool, inputs: Sequence[str | os.PathLike] = ()) -> None:
    """Raises UserError when ``out_dir`` cannot be (re)placed by :func:`atomic_directory`: it is a file,
    a non-empty directory without ``force``, holds one of ``inputs``, or its parent does not exist."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"{out_dir}: exists and is not a directory; choose another output directory")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not force:
        raise UserError(f"{out_dir}: output directory is not empty; choose another one or pass --force to replace it")
    resolved = out_dir.resolve()
    for path in inputs:
        if resolved in Path(path).resolve().parents:
            raise UserError(f"{path}: input lies inside the output directory {out_dir}, which would be replaced")
    if not out_dir.resolve().parent.is_dir():
        raise UserError(f"{out_dir}: parent directory does not exist; create it first")


def sync_filesystem(path: str | os.PathLike) -> None:
    """Flushes everything written to the file system holding ``path`` to disk: Linux's syncfs, which
    Python's os module lacks (os.sync, every file system, where libc has no syncfs)."""
    import ctypes  # only here: costs start-up time for every command otherwise

    syncfs = getattr(ctypes.CDLL(None, use_errno=True), "syncfs", None)
    if syncfs is None:
        os.sync()
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        if syncfs(fd) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"syncfs failed: {os.strerror(err)}", str(path))
    finally:
        os.close(fd)


def fsync_path(path: str | os.PathLike) -> None:
    """fsync of a file or directory by name (a directory's fsync makes its renames durable)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
