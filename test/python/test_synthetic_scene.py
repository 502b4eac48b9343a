"""The synthetic scene's ray caster and map sampler against hand-computed geometry."""

import numpy as np
from fixtures import synthetic_scene as ss


def small_scene() -> ss.Scene:
    boxes = np.array([[[10.0, -2.0, 0.0], [12.0, 2.0, 3.0]]])
    poles = np.array([[0.0, 5.0, 0.5, 4.0]])
    return ss.Scene(boxes=boxes, poles=poles, ground=(-50.0, 50.0, -50.0, 50.0))


def test_rays_hit_ground_box_and_pole_at_closed_form_distances() -> None:
    scene = small_scene()
    origin = np.array([0.0, 0.0, 1.5])
    down = np.array([0.0, 0.0, -1.0])
    toward_box = np.array([1.0, 0.0, 0.0])
    toward_pole = np.array([0.0, 1.0, 0.0])
    slanted = np.array([1.0, 0.0, -0.1]) / np.linalg.norm([1.0, 0.0, -0.1])  # hits ground at x = 15 m
    up = np.array([0.0, 0.0, 1.0])
    t = ss.raycast(scene, origin, np.array([down, toward_box, toward_pole, slanted, up]), max_range=100.0)
    np.testing.assert_allclose(t[:3], [1.5, 10.0, 4.5])
    # the slanted ray meets the box face x = 10 at z = 1.5 - 1.0 = 0.5 m, before the ground
    np.testing.assert_allclose(t[3], 10.0 / slanted[0])
    assert np.isinf(t[4])


def test_box_behind_the_origin_is_hit_across_the_azimuth_wrap() -> None:
    """A box straddling azimuth +-pi (rays are culled by azimuth): rays just above and below pi hit its face."""
    scene = ss.Scene(
        boxes=np.array([[[-12.0, -2.0, 0.0], [-10.0, 2.0, 3.0]]]), poles=np.zeros((0, 4)), ground=(0, 0, 0, 0)
    )
    origin = np.array([0.0, 0.0, 1.5])
    angles = np.array([np.pi - 0.1, -np.pi + 0.1, np.pi, 0.5 * np.pi])
    dirs = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(4)])
    t = ss.raycast(scene, origin, dirs, max_range=100.0)
    np.testing.assert_allclose(t[:3], 10.0 / np.abs(np.cos(angles[:3])))
    assert np.isinf(t[3])


def test_max_range_turns_far_hits_into_misses() -> None:
    t = ss.raycast(small_scene(), np.array([0.0, 0.0, 1.5]), np.array([[1.0, 0.0, 0.0]]), max_range=9.0)
    assert np.isinf(t[0])


def test_scan_points_lie_on_scene_surfaces() -> None:
    scene = ss.make_scene(seed=3, length=60.0)
    drive = ss.Drive(duration=1.0)
    pose = drive.pose(0.5)
    points = ss.scan(scene, pose, np.random.default_rng(0), noise=0.0)
    assert len(points) > 20000
    world = (pose @ ss.lidar_mount() @ np.c_[points, np.ones(len(points))].T).T[:, :3]
    on_ground = np.abs(world[:, 2]) < 1e-3
    on_box = np.zeros(len(world), dtype=bool)
    for lo, hi in scene.boxes:
        inside = np.all((world >= lo - 1e-3) & (world <= hi + 1e-3), axis=1)
        on_box |= inside
    on_pole = np.zeros(len(world), dtype=bool)
    for x, y, r, h in scene.poles:
        d = np.hypot(world[:, 0] - x, world[:, 1] - y)
        on_pole |= (np.abs(d - r) < 1e-3) & (world[:, 2] <= h + 1e-3)
    assert np.all(on_ground | on_box | on_pole)


def test_drive_heading_follows_the_velocity() -> None:
    drive = ss.Drive(duration=2.0)
    a, b = drive.pose(1.0), drive.pose(1.0 + 1e-6)
    velocity = (b[:3, 3] - a[:3, 3]) / 1e-6
    np.testing.assert_allclose(a[:3, 0], velocity / np.linalg.norm(velocity), atol=1e-6)


def test_gyro_rate_is_the_derivative_of_the_heading() -> None:
    drive = ss.Drive(duration=20.0)
    t = np.linspace(0.0, 19.0, 50)
    h = 1e-6
    yaw = [np.arctan2(drive.pose(x)[1, 0], drive.pose(x)[0, 0]) for x in np.r_[t - h, t + h]]
    finite_difference = (np.array(yaw[t.size :]) - np.array(yaw[: t.size])) / (2 * h)
    rates = drive.angular_velocity(t)
    np.testing.assert_allclose(rates[:, 2], finite_difference, atol=1e-6)
    assert np.all(rates[:, :2] == 0.0)
    assert np.abs(rates[:, 2]).max() > 0.05  # the weave turns: the gyro has something to predict


def test_sampled_map_covers_each_box_face() -> None:
    scene = small_scene()
    points = ss.sample_map(scene, spacing=0.25, noise=0.0)
    face = points[np.abs(points[:, 0] - 10.0) < 1e-6]
    assert face[:, 1].min() <= -1.99 and face[:, 1].max() >= 1.99
    assert face[:, 2].max() >= 2.99
    # no ground points under the box
    under = (points[:, 0] > 10.01) & (points[:, 0] < 11.99) & (np.abs(points[:, 1]) < 1.99) & (points[:, 2] == 0)
    assert not under.any()
