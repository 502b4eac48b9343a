"""TUM trajectories, pose interpolation (closed form: linear position, half-angle yaw), keyframe spacing."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.blocks.keyframes import Scan, select_keyframes
from grid_puzzle_localization.blocks.poses import parse_extrinsic, read_tum
from grid_puzzle_localization.errors import UserError


def test_interpolation_is_linear_in_position_and_slerp_in_rotation(tmp_path):
    q0 = Rotation.from_euler("z", 0.2).as_quat()
    q1 = Rotation.from_euler("z", 1.0).as_quat()
    path = tmp_path / "t.tum"
    path.write_text(
        f"# stamp x y z qx qy qz qw\n10.0 0 0 0 {' '.join(map(str, q0))}\n12.0 4 -2 1 {' '.join(map(str, q1))}\n"
    )
    trajectory = read_tum(path)
    poses, inside = trajectory.interpolate(np.array([9.0, 10.0, 10.5, 11.0, 12.0, 12.5]))
    np.testing.assert_array_equal(inside, [False, True, True, True, True, False])
    np.testing.assert_allclose(poses[2, :3, 3], [1.0, -0.5, 0.25], atol=1e-12)
    np.testing.assert_allclose(poses[3, :3, :3], Rotation.from_euler("z", 0.6).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(poses[4, :3, 3], [4.0, -2.0, 1.0], atol=1e-12)
    np.testing.assert_array_equal(poses[0], np.eye(4))  # outside: not extrapolated


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1 2 3\n", "expected 8 numbers"),
        ("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", "strictly increasing"),
        ("1 0 0 0 0 0 0 0\n", "all zeros"),
        ("# only a comment\n", "no poses"),
    ],
)
def test_bad_trajectory_is_a_user_error(tmp_path, text, message):
    path = tmp_path / "bad.tum"
    path.write_text(text)
    with pytest.raises(UserError, match=message):
        read_tum(path)


def test_extrinsic_needs_seven_numbers():
    with pytest.raises(UserError, match="7 finite numbers"):
        parse_extrinsic([0.0] * 6)
    np.testing.assert_allclose(parse_extrinsic([1, 2, 3, 0, 0, 0, 2])[:3, 3], [1, 2, 3])  # quaternion normalised


def test_keyframes_every_spacing_metres():
    def scan(x: float) -> Scan:
        pose = np.eye(4)
        pose[0, 3] = x
        return Scan(x, pose, lambda: np.zeros((0, 3)))

    xs = [0.0, 0.5, 1.0, 1.9, 2.0, 2.5, 3.0, 3.25, 5.0]
    kept = [s.stamp for s in select_keyframes(map(scan, xs), 1.0)]
    assert kept == [0.0, 1.0, 2.0, 3.0, 5.0]
    assert [s.stamp for s in select_keyframes(map(scan, xs), 0.0)] == xs
