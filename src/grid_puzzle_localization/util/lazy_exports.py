"""Package names imported from their submodule on first use (PEP 562), so a process that needs one
part of a package (the tile provider reading tiles) does not load the rest and what it imports."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, exports: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` whose public names ``exports``
    maps to the submodule defining each."""

    def getattr_(name: str) -> Any:
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{exports[name]}"), name)

    def dir_() -> list[str]:
        return sorted([*vars(importlib.import_module(package)), *exports])

    return getattr_, dir_
