"""atheris target: the PCD header parser (pcd.header.parse_header) on arbitrary bytes."""

from __future__ import annotations

from pathlib import Path

import atheris
from harness import rejects_cleanly, run

with atheris.instrument_imports(include=["grid_puzzle_localization"]):
    from grid_puzzle_localization.pcd.header import parse_header

NAME = Path("fuzzed.pcd")


def test_one_input(data: bytes) -> None:
    def parse() -> None:
        header = parse_header(data, NAME)
        header.dtype  # noqa: B018 (the record type must build for any accepted header)

    rejects_cleanly(parse, NAME)


if __name__ == "__main__":
    run(test_one_input)
