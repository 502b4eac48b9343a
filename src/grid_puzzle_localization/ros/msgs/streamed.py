"""A PointCloud2 message whose points stay in numpy arrays until rospy serialises it: ``serialize``
writes the wire format (the one genpy writes for the plain message) straight from the arrays into
rospy's buffer.

Why: genpy serialises ``uint8[] data`` through ``struct.pack``, which makes a full copy before the
buffer write makes another, on top of the copy a PointCloud2 holds in ``data``. For a window of tiles
that is three window-sized copies per publish. Streamed, a message holds no copy of the points, and
publishing costs one copy (rospy's send buffer), only while there are subscribers: rospy serialises
nothing for a topic without connections.

The message keeps its other fields, but ``data`` stays empty: it is for publishing, not for reading
back in this process.
"""

from __future__ import annotations

import functools
import io
import struct
from collections.abc import Callable, Sequence

import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from grid_puzzle_localization.ros.msgs.cloud import byte_order_is_big, check_parts, fields_of

_U32 = struct.Struct("<I")
_HEADER = struct.Struct("<3I")  # seq, stamp secs, stamp nsecs
_CLOUD_SHAPE = struct.Struct("<2I")  # height, width
_FIELD_TAIL = struct.Struct("<IBI")  # offset, datatype, count
_CLOUD_LAYOUT = struct.Struct("<B2I")  # is_bigendian, point_step, row_step


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return _U32.pack(len(raw)) + raw


def _header(header: Header) -> bytes:
    return _HEADER.pack(header.seq, header.stamp.secs, header.stamp.nsecs) + _string(header.frame_id)


@functools.lru_cache(maxsize=64)
def _fields(dtype: np.dtype) -> bytes:
    """The serialised ``fields`` array of a cloud of ``dtype`` (the same for every tile of a window)."""
    fields = fields_of(dtype)
    return _U32.pack(len(fields)) + b"".join(
        _string(f.name) + _FIELD_TAIL.pack(f.offset, f.datatype, f.count) for f in fields
    )


def _cloud_prefix(header: bytes, dtype: np.dtype, width: int) -> bytes:
    """Every byte of a serialised unorganised PointCloud2 before its point bytes (ending with the
    length of ``data``); ``header``: the serialised std_msgs/Header."""
    return b"".join(
        [
            header,
            _CLOUD_SHAPE.pack(1, width),
            _fields(dtype),
            _CLOUD_LAYOUT.pack(byte_order_is_big(dtype), dtype.itemsize, dtype.itemsize * width),
            _U32.pack(dtype.itemsize * width),
        ]
    )


def _reserve(buff, nbytes: int) -> None:
    """Grows a BytesIO once to hold ``nbytes`` more from its position, instead of step by step through
    the many writes that follow (each growth by 1/8 reallocates)."""
    if not isinstance(buff, io.BytesIO):
        return
    pos = buff.tell()
    if pos + nbytes > buff.seek(0, io.SEEK_END):
        buff.seek(pos + nbytes - 1)
        buff.write(b"\0")
    buff.seek(pos)


def _write_cloud(buff, prefix: bytes, parts: Sequence[np.ndarray], is_dense: bool) -> None:
    buff.write(prefix)
    for part in parts:
        buff.write(part)
    buff.write(b"\x01" if is_dense else b"\x00")


class StreamedCloud(PointCloud2):
    """An unorganised PointCloud2 of the arrays ``source()`` returns when the message is serialised
    (all of ``dtype``, C-contiguous). Latched, it is therefore always the current state of the source:
    a late subscriber gets the arrays as they are when it connects. ``is_dense``: every point has
    finite x, y and z (the caller's guarantee)."""

    # No __slots__ of its own: genpy walks ``self.__slots__`` as the message's field list.

    def __init__(self, header: Header, dtype: np.dtype, source: Callable[[], Sequence[np.ndarray]], is_dense: bool):
        super().__init__(header=header, height=1, is_dense=is_dense)
        self._dtype = np.dtype(dtype)
        self._source = source
        self.fields = fields_of(self._dtype)

    def serialize(self, buff) -> None:
        parts = self._source()
        check_parts(parts, self._dtype)
        prefix = _cloud_prefix(_header(self.header), self._dtype, sum(len(p) for p in parts))
        _reserve(buff, len(prefix) + sum(p.nbytes for p in parts) + 1)
        _write_cloud(buff, prefix, parts, self.is_dense)
