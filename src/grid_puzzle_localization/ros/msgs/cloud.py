"""numpy structured arrays <-> sensor_msgs/PointCloud2, straight from and to buffers (no per-point objects).

Any fields work: each named field of the array becomes a PointField with its byte offset, PointField
datatype and count (a sub-array field such as ``('normal', 'f4', (3,))`` has count 3). Field types
PointField cannot express (64-bit integers, strings, nested records) are refused with a ValueError.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

# PointField datatype <-> numpy base type (byte order applied separately).
_DATATYPES: dict[int, np.dtype] = {
    PointField.INT8: np.dtype(np.int8),
    PointField.UINT8: np.dtype(np.uint8),
    PointField.INT16: np.dtype(np.int16),
    PointField.UINT16: np.dtype(np.uint16),
    PointField.INT32: np.dtype(np.int32),
    PointField.UINT32: np.dtype(np.uint32),
    PointField.FLOAT32: np.dtype(np.float32),
    PointField.FLOAT64: np.dtype(np.float64),
}
_CODES = {(dt.kind, dt.itemsize): code for code, dt in _DATATYPES.items()}
_LITTLE = sys.byteorder == "little"


def fields_of(dtype: np.dtype) -> list[PointField]:
    """PointFields describing a structured dtype (offsets as in the dtype, padding kept)."""
    return list(_fields_of(dtype))


@functools.lru_cache(maxsize=64)
def _fields_of(dtype: np.dtype) -> tuple[PointField, ...]:
    # Cached: a window message holds thousands of tile clouds of one dtype.
    if dtype.names is None:
        raise ValueError(f"a point cloud needs a structured dtype with named fields, not {dtype}")
    fields = []
    for name in dtype.names:
        field_dtype, offset = dtype.fields[name][:2]
        base = field_dtype.base
        code = _CODES.get((base.kind, base.itemsize))
        if code is None:
            raise ValueError(f"field '{name}' has type {base}, which PointField cannot express")
        fields.append(PointField(name=name, offset=offset, datatype=code, count=int(np.prod(field_dtype.shape))))
    return tuple(fields)


def byte_order_is_big(dtype: np.dtype) -> bool:
    """True when the fields are big-endian. Mixed byte orders are refused."""
    orders = {dtype.fields[n][0].base.byteorder for n in dtype.names} - {"|"}
    big = {o for o in orders if o == ">" or (o == "=" and not _LITTLE)}
    if big and len(big) != len(orders):
        raise ValueError(f"fields mix byte orders in {dtype}; convert the array to one byte order first")
    return bool(big)


def array_to_cloud(points: np.ndarray, frame_id: str = "", stamp=None, header: Header | None = None) -> PointCloud2:
    """An unorganised (height 1) PointCloud2 holding a copy of ``points``' bytes. ``is_dense`` is true
    when every float field is finite."""
    points = np.ascontiguousarray(points)
    return cloud_from_parts([points], points.dtype, frame_id, stamp, header)


def check_parts(parts: Sequence[np.ndarray], dtype: np.dtype) -> None:
    """Raises ValueError unless every part is a C-contiguous array of ``dtype``."""
    for part in parts:
        if part.dtype != dtype or not part.flags.c_contiguous:
            raise ValueError(f"every part must be a contiguous array of {dtype} (got {part.dtype})")


def cloud_from_parts(
    parts: Sequence[np.ndarray], dtype: np.dtype, frame_id: str = "", stamp=None, header: Header | None = None
) -> PointCloud2:
    """One unorganised PointCloud2 of several arrays of the same dtype, copied once straight into the
    message's data (no concatenated intermediate array)."""
    check_parts(parts, dtype)
    msg = PointCloud2()
    msg.header = header if header is not None else Header(frame_id=frame_id)
    if stamp is not None:
        msg.header.stamp = stamp
    msg.height = 1
    msg.width = sum(len(p) for p in parts)
    msg.fields = fields_of(dtype)
    msg.is_bigendian = byte_order_is_big(dtype)
    msg.point_step = dtype.itemsize
    msg.row_step = msg.point_step * msg.width
    msg.data = b"".join(memoryview(p) for p in parts)
    points = np.frombuffer(msg.data, dtype=dtype)
    msg.is_dense = all(bool(np.isfinite(points[n]).all()) for n in dtype.names if dtype.fields[n][0].base.kind == "f")
    return msg


def cloud_dtype(msg: PointCloud2) -> np.dtype:
    """The structured dtype of one point of ``msg`` (itemsize = point_step)."""
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if f.datatype not in _DATATYPES:
            raise ValueError(f"PointCloud2 field '{f.name}' has unknown datatype {f.datatype}")
        if f.name in names:
            continue
        base = _DATATYPES[f.datatype].newbyteorder(order)
        names.append(f.name)
        formats.append((base, (f.count,)) if f.count > 1 else base)
        offsets.append(f.offset)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": msg.point_step})


def cloud_to_array(msg: PointCloud2) -> np.ndarray:
    """The points of ``msg`` as a read-only structured array viewing ``msg.data`` (rows of an
    organised cloud are concatenated; row padding beyond width * point_step is skipped)."""
    dtype = cloud_dtype(msg)
    n = msg.width * msg.height
    if n == 0:
        return np.empty(0, dtype=dtype)
    if len(msg.data) < msg.row_step * (msg.height - 1) + msg.width * msg.point_step:
        raise ValueError(
            f"PointCloud2 data holds {len(msg.data)} bytes, too few for {msg.height} rows of {msg.width} points"
            f" (point_step {msg.point_step}, row_step {msg.row_step})"
        )
    if msg.row_step == msg.width * msg.point_step:
        return np.frombuffer(msg.data, dtype=dtype, count=n)
    rows = np.lib.stride_tricks.as_strided(
        np.frombuffer(msg.data, dtype=np.uint8),
        shape=(msg.height, msg.width * msg.point_step),
        strides=(msg.row_step, 1),
    )
    return np.ascontiguousarray(rows).view(dtype).reshape(n)
