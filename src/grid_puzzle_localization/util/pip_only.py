"""Modules that only pip installs (listed in requirements.txt; rosdep cannot install them). Each is imported where a
feature needs it, so a robot with only what rosdep installs runs the nodes and every other `gpm` command."""

from __future__ import annotations

import importlib
from types import ModuleType

from grid_puzzle_localization.errors import UserError


def import_pip_only(module: str, distribution: str, needed_for: str) -> ModuleType:
    """Imports ``module`` from the PyPI distribution ``distribution``; when it is missing, raises a UserError that
    names what needs it and how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise UserError(
            f"{needed_for} needs the Python package {distribution}, which rosdep cannot install: "
            f"`python3 -m pip install {distribution}` (or `-r requirements.txt` from this package)"
        ) from exc
