"""The ``ascii`` PCD encoding: one point per line, values separated by spaces, fields in header order.

Floats are written with enough significant digits to read back bit for bit (9 for float32, 17 for
float64). As in PCL, a 4-byte float field named ``rgb`` is written as the unsigned integer holding
its bits, because opaque packed colours are NaN patterns as floats; both forms are read.
"""

from __future__ import annotations

import os

import numpy as np

from grid_puzzle_localization.errors import PcdError

_FLOAT_FORMAT = {2: "%.5g", 4: "%.9g", 8: "%.17g"}


def _is_packed_rgb(name: str, base: np.dtype) -> bool:
    return name == "rgb" and base == np.dtype("<f4")


def _columns(dtype: np.dtype):
    """(name, base dtype, count) per field."""
    for name in dtype.names:
        field = dtype.fields[name][0]
        if field.subdtype:
            yield name, field.subdtype[0], int(field.shape[0])
        else:
            yield name, field, 1


def decode_ascii_lines(lines: list[bytes], dtype: np.dtype, path: str | os.PathLike, first_line: int) -> np.ndarray:
    """Decodes data lines into records of ``dtype``. ``first_line`` (1-based line number in the file)
    only serves error messages."""
    columns = list(_columns(dtype))
    ncols = sum(count for _, _, count in columns)
    tokens = b" ".join(lines).split()
    if len(tokens) != len(lines) * ncols:
        for k, line in enumerate(lines):
            if len(line.split()) != ncols:
                raise PcdError(
                    f"{path}: line {first_line + k} has {len(line.split())} values but the header declares {ncols}"
                )
    table = np.array(tokens, dtype=np.bytes_).reshape(len(lines), ncols)
    out = np.empty(len(lines), dtype=dtype)
    c = 0
    for name, base, count in columns:
        cells = table[:, c : c + count] if count > 1 else table[:, c]
        c += count
        try:
            if _is_packed_rgb(name, base):
                try:
                    out[name] = cells.astype(np.uint32).view(np.float32)
                except ValueError:
                    out[name] = cells.astype(np.float32)
            else:
                out[name] = cells.astype(base)
        except (ValueError, OverflowError) as err:
            raise PcdError(
                f"{path}: field '{name}' in data lines {first_line}-{first_line + len(lines) - 1}"
                f" holds a value that is not a {base} ({err})"
            ) from None
    return out


def encode_ascii(points: np.ndarray) -> bytes:
    """Text of the records, one line each (with a trailing newline when there are points)."""
    if len(points) == 0:
        return b""
    texts = []
    for name, base, count in _columns(points.dtype):
        values = points[name].reshape(len(points), count)
        if _is_packed_rgb(name, base):
            values, fmt = values.view(np.uint32), "%d"
        else:
            fmt = _FLOAT_FORMAT[base.itemsize] if base.kind == "f" else "%d"
        texts.extend(np.char.mod(fmt, values[:, k]) for k in range(count))
    lines = texts[0]
    for column in texts[1:]:
        lines = np.char.add(np.char.add(lines, " "), column)
    return ("\n".join(lines.tolist()) + "\n").encode("ascii")
