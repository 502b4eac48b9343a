"""PCD v0.7 header: parsing, the numpy record type it declares, and its text form.

A PCD file is a text header (one ``KEY value...`` line per entry, ``#`` comments allowed) ending with
the ``DATA`` line, followed by the point records. Records are packed little-endian, fields in header
order, a field with ``COUNT n`` holding ``n`` values (numpy sub-array of shape ``(n,)``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.util.iteration import zip_equal

ENCODINGS = ("ascii", "binary", "binary_compressed")
IDENTITY_VIEWPOINT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
_MAX_HEADER_BYTES = 1 << 16
_MAX_RECORD_BYTES = (1 << 31) - 1  # numpy's limit on a record type (and far beyond any real PCD layout)
_KINDS = {"I": "i", "U": "u", "F": "f"}
_VALID_SIZES = {"I": (1, 2, 4, 8), "U": (1, 2, 4, 8), "F": (2, 4, 8)}
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


@dataclass(frozen=True)
class PcdHeader:
    """What a PCD header declares. ``header_bytes`` is the byte offset where the data section starts."""

    fields: tuple[str, ...]
    sizes: tuple[int, ...]
    types: tuple[str, ...]
    counts: tuple[int, ...]
    width: int
    height: int
    points: int
    data: str
    viewpoint: tuple[float, ...] = IDENTITY_VIEWPOINT
    version: str = "0.7"
    header_bytes: int = 0

    @property
    def dtype(self) -> np.dtype:
        """Packed numpy record type of one point (field names as in the file)."""
        return np.dtype(
            [
                (name, f"<{_KINDS[t]}{size}", (count,)) if count > 1 else (name, f"<{_KINDS[t]}{size}")
                for name, size, t, count in zip_equal(self.fields, self.sizes, self.types, self.counts)
            ]
        )

    @property
    def record_bytes(self) -> int:
        return sum(s * c for s, c in zip_equal(self.sizes, self.counts))

    @property
    def data_bytes(self) -> int:
        """Bytes of the uncompressed point records (POINTS x record size)."""
        return self.points * self.record_bytes

    def text(self, length: int = 0) -> str:
        """The header as written to a file (ends with the DATA line and its newline). A ``length``
        larger than the natural one pads the leading comment line with spaces to exactly that many
        bytes, so a header can be rewritten in place once the point count is known."""
        lines = [
            "# .PCD v0.7 - Point Cloud Data file format",
            f"VERSION {self.version}",
            "FIELDS " + " ".join(self.fields),
            "SIZE " + " ".join(map(str, self.sizes)),
            "TYPE " + " ".join(self.types),
            "COUNT " + " ".join(map(str, self.counts)),
            f"WIDTH {self.width}",
            f"HEIGHT {self.height}",
            "VIEWPOINT " + " ".join(f"{v:.17g}" for v in self.viewpoint),
            f"POINTS {self.points}",
            f"DATA {self.data}",
            "",
        ]
        text = "\n".join(lines)
        if length > len(text):
            lines[0] += " " * (length - len(text))
            text = "\n".join(lines)
        return text


def header_for(
    dtype: np.dtype, points: int, encoding: str, path: str | os.PathLike, viewpoint=IDENTITY_VIEWPOINT
) -> PcdHeader:
    """Header describing ``points`` records of the structured ``dtype`` (an unorganised cloud)."""
    if encoding not in ENCODINGS:
        raise PcdError(f"{path}: unknown PCD encoding '{encoding}'; use one of {', '.join(ENCODINGS)}")
    if dtype.names is None:
        raise PcdError(f"{path}: points must be a numpy structured array with named fields, got dtype {dtype}")
    sizes, types, counts = [], [], []
    for name in dtype.names:
        field = dtype.fields[name][0]
        base, shape = (field.subdtype[0], field.shape) if field.subdtype else (field, ())
        kind = {"i": "I", "u": "U", "f": "F"}.get(base.kind)
        if kind is None or base.itemsize not in _VALID_SIZES[kind] or len(shape) > 1 or " " in name:
            raise PcdError(f"{path}: field '{name}' of type {field} cannot be stored in a PCD file")
        sizes.append(base.itemsize)
        types.append(kind)
        counts.append(int(shape[0]) if shape else 1)
    return PcdHeader(
        fields=tuple(dtype.names),
        sizes=tuple(sizes),
        types=tuple(types),
        counts=tuple(counts),
        width=points,
        height=1,
        points=points,
        data=encoding,
        viewpoint=tuple(float(v) for v in viewpoint),
    )


def read_pcd_header(path: str | os.PathLike) -> PcdHeader:
    """Parses and checks the header of a PCD file. Raises PcdError naming the file and the problem."""
    try:
        with open(path, "rb") as f:
            raw = f.read(_MAX_HEADER_BYTES)
    except FileNotFoundError:
        raise PcdError(f"{path}: no such file; check the path") from None
    except OSError as err:
        raise PcdError(f"{path}: cannot read ({err.strerror})") from None
    return parse_header(raw, path)


def parse_header(raw: bytes, path: str | os.PathLike) -> PcdHeader:
    """Parses the header at the start of ``raw`` (the first bytes of the file)."""
    entries: dict[str, list[str]] = {}
    offset = 0
    while "DATA" not in entries:
        end = raw.find(b"\n", offset)
        if end < 0:
            raise PcdError(f"{path}: header has no DATA line; not a PCD file or truncated header")
        line = raw[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _KEYS:
            raise PcdError(f"{path}: bad header line '{line}' (unknown key {key})")
        entries[key] = values
    return _checked_header(entries, offset, path)


def _checked_header(entries: dict[str, list[str]], offset: int, path) -> PcdHeader:
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "POINTS"):
        if key not in entries:
            raise PcdError(f"{path}: header lacks the {key} line")
    fields = _unique_names(entries["FIELDS"])
    n = len(fields)
    sizes = _ints(entries, "SIZE", path)
    types = tuple(entries["TYPE"])
    counts = _ints(entries, "COUNT", path) if "COUNT" in entries else (1,) * n
    for key, values in (("SIZE", sizes), ("TYPE", types), ("COUNT", counts)):
        if len(values) != n:
            raise PcdError(f"{path}: {key} has {len(values)} entries but FIELDS names {n} fields")
    for name, size, t, count in zip_equal(fields, sizes, types, counts):
        if t not in _VALID_SIZES or size not in _VALID_SIZES[t] or count < 1:
            raise PcdError(f"{path}: field '{name}' has unsupported TYPE {t} SIZE {size} COUNT {count}")
    record_bytes = sum(s * c for s, c in zip_equal(sizes, counts))
    if record_bytes > _MAX_RECORD_BYTES:
        raise PcdError(f"{path}: SIZE x COUNT make a point record of {record_bytes} bytes; the COUNT line is corrupt")
    width, height, points = (_ints(entries, key, path, single=True)[0] for key in ("WIDTH", "HEIGHT", "POINTS"))
    if width * height != points:
        raise PcdError(f"{path}: WIDTH {width} x HEIGHT {height} disagrees with POINTS {points}")
    data = " ".join(entries["DATA"]).lower()
    if data not in ENCODINGS:
        raise PcdError(f"{path}: unknown DATA encoding '{data}'; supported are {', '.join(ENCODINGS)}")
    viewpoint = IDENTITY_VIEWPOINT
    if "VIEWPOINT" in entries:
        try:
            viewpoint = tuple(float(v) for v in entries["VIEWPOINT"])
        except ValueError:
            viewpoint = ()
        if len(viewpoint) != 7:
            raise PcdError(f"{path}: bad header line 'VIEWPOINT {' '.join(entries['VIEWPOINT'])}' (7 numbers)")
    version = entries.get("VERSION", ["0.7"])
    if not version:
        raise PcdError(f"{path}: bad header line 'VERSION' (expected the format version, e.g. VERSION 0.7)")
    return PcdHeader(fields, sizes, types, counts, width, height, points, data, viewpoint, version[0], offset)


def _ints(entries: dict[str, list[str]], key: str, path, single: bool = False) -> tuple[int, ...]:
    values = entries[key]
    try:
        ints = tuple(int(v) for v in values)
    except ValueError:
        ints = ()
    if not ints or any(v < 0 for v in ints) or (single and len(ints) != 1):
        raise PcdError(f"{path}: bad header line '{key} {' '.join(values)}' (expected non-negative integers)")
    return ints


def _unique_names(names: list[str]) -> tuple[str, ...]:
    """PCL names padding fields '_'; numpy needs unique names, so repeats get a numeric suffix."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        k = seen.get(name, 0)
        seen[name] = k + 1
        out.append(name if k == 0 else f"{name}{k}")
    return tuple(out)
