"""An output directory that appears complete or not at all.

Everything is written into a temporary directory beside OUT_DIR, which is renamed onto OUT_DIR only
when the work succeeded; on any failure it is removed. An existing non-empty OUT_DIR is refused
unless ``force`` is set, in which case it is replaced (moved aside, then deleted) at commit time.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from grid_puzzle_localization.errors import UserError


def check_output_dir(out_dir: Path, force: bool, inputs: Sequence[Path] = ()) -> None:
    """Raises UserError when OUT_DIR cannot be (re)placed."""
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
