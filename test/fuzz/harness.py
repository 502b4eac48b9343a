"""What every Python fuzz target checks: a reader either returns or raises UserError (PcdError is one) whose
message names the input file; any other exception is a finding, and atheris reports it with the input."""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import atheris

with atheris.instrument_imports(include=["grid_puzzle_localization"]):
    from grid_puzzle_localization.errors import UserError


class UnnamedInputError(AssertionError):
    """A rejection whose message does not say which file was bad."""


def rejects_cleanly(read: Callable[[], object], path: Path) -> None:
    """Runs ``read``; a UserError must name ``path`` (a file, or the directory of the files read)."""
    try:
        read()
    except UserError as err:
        if str(path) not in str(err):
            raise UnnamedInputError(f"error does not name {path}: {err}") from err


def scratch_dir() -> Path:
    """A private directory for the input files (tmpfs when TMPDIR points there)."""
    return Path(tempfile.mkdtemp(prefix="fuzz_", dir=os.environ.get("TMPDIR")))


def run(test_one_input: Callable[[bytes], None]) -> None:
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()
