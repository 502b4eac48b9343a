"""cloud_msg against sensor_msgs.point_cloud2 (read_points / create_cloud) as the independent reference."""

import numpy as np
import pytest
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

from grid_puzzle_localization.ros.msgs.cloud import array_to_cloud, cloud_from_parts, cloud_to_array

MIXED = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("intensity", "<f4"),
        ("ring", "<u2"),
        ("label", "i1"),
        ("flag", "u1"),
        ("t", "<f8"),
        ("normal", "<f4", (3,)),
        ("id", "<i4"),
        ("w", "<i2"),
        ("u", "<u4"),
    ]
)


def random_points(n, dtype=MIXED, seed=0):
    rng = np.random.default_rng(seed)
    pts = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        base = dtype.fields[name][0].base
        shape = (n, *dtype.fields[name][0].shape)
        if base.kind == "f":
            pts[name] = rng.normal(0, 100, shape)
        else:
            info = np.iinfo(base)
            pts[name] = rng.integers(info.min, info.max, shape, endpoint=True)
    return pts


def rows_of(points):
    """Each point flattened to a tuple of Python numbers, in field order (as read_points yields)."""
    out = []
    for p in points.tolist():
        row = []
        for v in p:
            row.extend(np.ravel(v).tolist() if isinstance(v, np.ndarray) else [v])
        out.append(tuple(row))
    return out


@pytest.mark.parametrize("n", [0, 1, 257])
def test_array_to_cloud_reads_back_with_read_points(n):
    pts = random_points(n)
    msg = array_to_cloud(pts, frame_id="map")
    assert msg.header.frame_id == "map" and msg.width == n and msg.height == 1
    assert msg.point_step == MIXED.itemsize and msg.row_step == n * MIXED.itemsize
    assert [f.name for f in msg.fields] == list(MIXED.names)
    assert [f.count for f in msg.fields if f.name == "normal"] == [3]
    expected = rows_of(pts)
    got = list(point_cloud2.read_points(msg))
    assert len(got) == n
    np.testing.assert_array_equal(np.array(got, dtype=np.float64), np.array(expected, dtype=np.float64))
    assert msg.is_dense


def test_cloud_to_array_reads_a_cloud_made_by_create_cloud():
    fields = [
        PointField("x", 0, PointField.FLOAT32, 1),
        PointField("y", 4, PointField.FLOAT32, 1),
        PointField("z", 8, PointField.FLOAT32, 1),
        # 4 bytes of padding, like PCL's PointXYZ
        PointField("intensity", 16, PointField.FLOAT64, 1),
        PointField("ring", 24, PointField.UINT16, 1),
    ]
    rng = np.random.default_rng(3)
    rows = [
        (*rng.normal(size=3).astype(np.float32).tolist(), float(rng.normal()), int(rng.integers(0, 64)))
        for _ in range(50)
    ]
    msg = point_cloud2.create_cloud(Header(frame_id="velodyne"), fields, rows)
    arr = cloud_to_array(msg)
    assert arr.dtype.names == ("x", "y", "z", "intensity", "ring")
    assert arr.dtype.itemsize == msg.point_step
    for k, name in enumerate(arr.dtype.names):
        np.testing.assert_array_equal(arr[name], np.array([r[k] for r in rows], dtype=arr.dtype[name]))


def test_round_trip_keeps_bytes_and_dtype_offsets():
    pts = random_points(100, seed=5)
    back = cloud_to_array(array_to_cloud(pts))
    assert back.tobytes() == pts.tobytes()
    for name in MIXED.names:
        np.testing.assert_array_equal(back[name], pts[name])


def test_big_endian_arrays_are_flagged_and_read_correctly():
    dtype = np.dtype([("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("i", ">u2")])
    pts = random_points(20, dtype, seed=9)
    msg = array_to_cloud(pts)
    assert msg.is_bigendian
    np.testing.assert_array_equal(np.array(list(point_cloud2.read_points(msg))), np.array(rows_of(pts)))
    np.testing.assert_array_equal(cloud_to_array(msg)["i"], pts["i"])


def test_organised_cloud_with_row_padding():
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    pts = random_points(12, dtype, seed=2).reshape(3, 4)
    msg = PointCloud2()
    msg.height, msg.width = 3, 4
    msg.fields = [PointField(n, 4 * k, PointField.FLOAT32, 1) for k, n in enumerate("xyz")]
    msg.point_step, msg.row_step = 12, 12 * 4 + 8
    msg.data = b"".join(row.tobytes() + b"\xff" * 8 for row in pts)
    arr = cloud_to_array(msg)
    ref = np.array(list(point_cloud2.read_points(msg)))
    np.testing.assert_array_equal(np.stack([arr["x"], arr["y"], arr["z"]], axis=1), ref)


def test_non_finite_points_make_the_cloud_not_dense_and_bad_types_are_refused():
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    pts = np.zeros(3, dtype=dtype)
    pts["x"][1] = np.nan
    assert not array_to_cloud(pts).is_dense
    with pytest.raises(ValueError, match="PointField"):
        array_to_cloud(np.zeros(2, dtype=[("x", "<f4"), ("stamp", "<u8")]))
    with pytest.raises(ValueError, match="structured"):
        array_to_cloud(np.zeros((2, 3), dtype=np.float32))


def test_truncated_data_is_refused():
    msg = array_to_cloud(random_points(4, np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])))
    msg.data = msg.data[:-1]
    with pytest.raises(ValueError, match="too few"):
        cloud_to_array(msg)


def test_cloud_from_parts_equals_the_concatenation():
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<u2")])
    parts = [random_points(n, dtype, seed=n) for n in (3, 0, 17, 1)]
    msg = cloud_from_parts(parts, dtype, frame_id="map")
    assert msg.width == 21 and msg.header.frame_id == "map"
    np.testing.assert_array_equal(
        np.array(list(point_cloud2.read_points(msg))), np.array(rows_of(np.concatenate(parts)))
    )
    empty = cloud_from_parts([], dtype)
    assert empty.width == 0 and empty.data == b"" and [f.name for f in empty.fields] == ["x", "y", "z", "i"]
    with pytest.raises(ValueError, match="contiguous"):
        cloud_from_parts([parts[0][::2]], dtype)
