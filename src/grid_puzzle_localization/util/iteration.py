"""Iteration helpers that Python 3.8 lacks: ``zip(..., strict=True)`` (3.10), ``itertools.pairwise`` (3.10)
and ``os.waitstatus_to_exitcode`` (3.9)."""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

T = TypeVar("T")
_MISSING = object()


def zip_equal(*iterables: Iterable[Any]) -> Iterator[tuple[Any, ...]]:
    """``zip`` that raises ValueError when the iterables have different lengths (like ``strict=True``)."""
    for items in itertools.zip_longest(*iterables, fillvalue=_MISSING):
        if any(item is _MISSING for item in items):  # `is`: items may be arrays
            raise ValueError("zip_equal: the iterables have different lengths")
        yield items


def pairwise(iterable: Iterable[T]) -> Iterator[tuple[T, T]]:
    """Consecutive pairs: s -> (s0, s1), (s1, s2), ..."""
    a, b = itertools.tee(iterable)
    next(b, None)
    return zip(a, b)


def exit_code(wait_status: int) -> int:
    """The exit code of a waitpid status; minus the signal number when a signal ended the process."""
    if os.WIFSIGNALED(wait_status):
        return -os.WTERMSIG(wait_status)
    return os.WEXITSTATUS(wait_status)
