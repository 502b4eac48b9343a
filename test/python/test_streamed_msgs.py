"""Streamed clouds against genpy's own serialisation of the equivalent plain clouds (byte for byte)."""

import io

import genpy
import numpy as np
import pytest
from rospy.msg import serialize_message
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from grid_puzzle_localization.ros.msgs.cloud import cloud_from_parts, cloud_to_array
from grid_puzzle_localization.ros.msgs.streamed import StreamedCloud

XYZI = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
MIXED = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("ring", "<u2"), ("normal", "<f4", (3,))])


def points(n, dtype, seed):
    rng = np.random.default_rng(seed)
    out = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        out[name] = rng.uniform(-50, 50, out[name].shape)
    return out


def header():
    return Header(seq=7, stamp=genpy.Time(1234, 567_000_000), frame_id="map")


def wire(msg, seq=None, buff=None):
    """The bytes a message serialises to; with ``seq``, as rospy frames them for the socket."""
    buff = io.BytesIO() if buff is None else buff
    if seq is None:
        msg.serialize(buff)
    else:
        serialize_message(buff, seq, msg)
    return buff.getvalue()


@pytest.mark.parametrize("dtype", [XYZI, MIXED])
@pytest.mark.parametrize("sizes", [[], [0], [5], [3, 0, 17, 1]])
def test_streamed_cloud_serialises_like_the_plain_cloud(dtype, sizes):
    parts = [points(n, dtype, seed) for seed, n in enumerate(sizes)]
    plain = cloud_from_parts(parts, dtype, header=header())
    streamed = StreamedCloud(header(), dtype, lambda: parts, is_dense=True)
    assert wire(streamed) == wire(plain)
    back = PointCloud2().deserialize(wire(streamed))
    want = np.concatenate(parts) if parts else np.empty(0, dtype)
    assert cloud_to_array(back).tobytes() == want.tobytes()


def test_streamed_cloud_is_framed_by_rospy_like_the_plain_cloud_in_a_reused_buffer():
    parts = [points(40, XYZI, 1), points(9, XYZI, 2)]
    used = io.BytesIO()
    used.write(b"x" * 100_000)  # rospy reuses its buffer: seek(0) and truncate(0) after each publish
    used.seek(0)
    used.truncate(0)
    streamed = wire(StreamedCloud(header(), XYZI, lambda: parts, True), seq=42, buff=used)
    assert streamed == wire(cloud_from_parts(parts, XYZI, header=header()), seq=42)


def test_a_streamed_cloud_serialises_the_source_as_it_is_at_that_moment():
    state = {"parts": [points(4, XYZI, 1)]}
    msg = StreamedCloud(header(), XYZI, lambda: state["parts"], True)
    first = wire(msg)
    state["parts"] = [points(4, XYZI, 1), points(6, XYZI, 3)]
    second = PointCloud2().deserialize(wire(msg))
    assert PointCloud2().deserialize(first).width == 4
    assert second.width == 10
    assert cloud_to_array(second).tobytes() == np.concatenate(state["parts"]).tobytes()


def test_is_dense_is_the_callers_statement():
    msg = StreamedCloud(header(), XYZI, lambda: [points(3, XYZI, 0)], is_dense=False)
    assert not PointCloud2().deserialize(wire(msg)).is_dense


def test_parts_of_another_dtype_or_not_contiguous_are_refused():
    with pytest.raises(ValueError, match="contiguous array"):
        wire(StreamedCloud(header(), XYZI, lambda: [points(4, MIXED, 0)], True))
    with pytest.raises(ValueError, match="contiguous array"):
        wire(StreamedCloud(header(), XYZI, lambda: [points(8, XYZI, 0)[::2]], True))
