"""Window maths against Table I written out by hand (the issue's table), and hypothesis properties."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.lost_search import LostSearchWindow, SearchRegion
from grid_puzzle_localization.provider.window import (
    NO_SECTOR,
    PoseSample,
    WindowConfig,
    WindowTracker,
    compute_window,
    sector_of,
    sector_of_degrees,
    window_covering,
)

# The Table I: (lo_deg, hi_deg, (du_min, du_max), (dv_min, dv_max)) in units of k.
TABLE_I = [
    (-20, 20, (0, 1), (0, 0)),
    (20, 70, (0, 1), (0, 1)),
    (70, 110, (0, 0), (0, 1)),
    (110, 160, (-1, 0), (0, 1)),
    (160, 200, (-1, 0), (0, 0)),
    (200, 250, (-1, 0), (-1, 0)),
    (250, 290, (0, 0), (-1, 0)),
    (290, 340, (0, 1), (-1, 0)),
]


def expected_ranges(sector, n, k):
    _, _, du, dv = TABLE_I[sector]
    return (-n + du[0] * k, n + du[1] * k), (-n + dv[0] * k, n + dv[1] * k)


@pytest.mark.parametrize("sector", range(8))
def test_each_sector_mid_angle_and_both_boundaries(sector):
    lo, hi, _, _ = TABLE_I[sector]
    # Half-open [lo, hi): lo belongs to this sector, hi to the next one.
    assert sector_of_degrees(lo) == sector
    assert sector_of_degrees(hi) == (sector + 1) % 8
    assert sector_of_degrees(hi - 1e-6) == sector
    assert sector_of(math.radians(lo)) == sector
    assert sector_of(math.radians((lo + hi) / 2)) == sector
    # The same angles one full turn away, and as negative angles.
    assert sector_of_degrees(lo + 360) == sector
    assert sector_of_degrees(lo - 360) == sector


@pytest.mark.parametrize("sector", range(8))
@pytest.mark.parametrize(("n", "k"), [(25, 20), (17, 10), (0, 3), (4, 0), (0, 0)])
def test_ranges_follow_table_i(sector, n, k):
    lo, hi, _, _ = TABLE_I[sector]
    mid = math.radians((lo + hi) / 2)
    w = compute_window(0.3, 0.3, mid, 2.0, n, k)
    assert w.sector == sector
    assert (w.u_range, w.v_range) == expected_ranges(sector, n, k)


def test_heading_from_atan2_distinguishes_up_from_down():
    # The paper's arccos gives 90 deg for both; atan2 puts them in sectors 2 (+y) and 6 (-y).
    tracker = WindowTracker(WindowConfig(n=1, k=2), s=2.0)
    tracker.update(PoseSample(1.0, 1.0))
    up = tracker.update(PoseSample(1.0, 3.0))
    assert up.sector == 2 and up.v_range == (-1, 3)
    down = tracker.update(PoseSample(1.0, -1.0))
    assert down.sector == 6 and down.v_range == (-3, 1)
    left = tracker.update(PoseSample(-3.0, -1.0))
    assert left.sector == 4 and math.degrees(left.theta) == 180.0


def test_negative_coordinates_center_and_bounds():
    w = compute_window(-0.1, -4.0, None, 2.0, 2, 5)
    assert w.center == (-1, -2)
    assert w.bounds == (-3, 1, -4, 0)
    assert w.sector == NO_SECTOR and math.isnan(w.theta)


@pytest.mark.parametrize(("s", "x", "i"), [(2.0, 3.9, 1), (2.0, -3.9, -2), (0.5, 0.74, 1), (0.5, -0.74, -2)])
def test_grid_sizes(s, x, i):
    w = compute_window(x, x, math.radians(45), s, 1, 2)
    assert w.center == (i, i)
    assert w.bounds == (i - 1, i + 3, i - 1, i + 3)


def test_n_zero_is_one_tile_plus_extension_and_k_zero_is_the_square():
    w = compute_window(1.0, 1.0, 0.0, 2.0, 0, 4)
    assert w.keys() == [(i, 0) for i in range(5)]
    assert compute_window(1.0, 1.0, None, 2.0, 0, 4).keys() == [(0, 0)]
    for deg in range(-180, 180, 15):
        assert compute_window(5.0, -5.0, math.radians(deg), 2.0, 3, 0).bounds == (-1, 5, -6, 0)


def test_keys_enumerate_the_bounds():
    w = compute_window(0.0, 0.0, math.radians(225), 1.0, 1, 1)
    keys = w.keys()
    assert keys == sorted(keys) and set(keys) == {(i, j) for i in range(-2, 2) for j in range(-2, 2)}


def test_standing_start_is_the_plain_square_and_standing_still_never_updates():
    tracker = WindowTracker(WindowConfig(n=2, k=3), s=2.0)
    first = tracker.update(PoseSample(5.0, 5.0))
    assert first.sector == NO_SECTOR and first.bounds == (0, 4, 0, 4)
    for _ in range(10):
        assert tracker.update(PoseSample(5.0 + 1e-3, 5.0)) is None
    assert tracker.predicted_windows() == []


def test_update_distance_gating_defaults_to_half_a_tile_and_keeps_the_heading():
    tracker = WindowTracker(WindowConfig(n=1, k=1), s=2.0)
    tracker.update(PoseSample(0.0, 0.0))
    assert tracker.update(PoseSample(1.0, 0.0)) is None  # exactly s/2: not farther than it
    w = tracker.update(PoseSample(1.01, 0.0))
    assert w is not None and w.sector == 0
    # A short wiggle backwards does not flip the heading (no update).
    assert tracker.update(PoseSample(0.5, 0.0)) is None
    assert tracker.window.sector == 0


def test_restart_recomputes_at_the_next_pose_and_keeps_the_heading():
    tracker = WindowTracker(WindowConfig(n=1, k=1), s=2.0)
    tracker.update(PoseSample(0.0, 0.0))
    tracker.update(PoseSample(3.0, 0.0))  # heading +x (sector 0)
    tracker.restart()
    w = tracker.update(PoseSample(3.1, 0.0))  # 0.1 m: would not update without the restart
    assert w is not None and w.sector == 0 and w.bounds == (0, 3, -1, 1)


def test_window_covering_a_square_holds_the_window_and_every_tile_meeting_the_square():
    s = 2.0
    window = compute_window(5.0, 5.0, 0.0, s, n=1, k=3)  # i 1..6, j 1..3
    grown = window_covering(window, 4.0, 4.0, 7.0, s)  # x, y in [-3, 11]: tiles -2..5
    assert grown.bounds == (-2, 6, -2, 5)
    assert grown.center == (2, 2) and grown.sector == NO_SECTOR
    assert window_covering(None, 4.0, 4.0, 7.0, s).bounds == (-2, 5, -2, 5)
    # A square inside the window leaves it as it is.
    assert window_covering(window, 5.0, 5.0, 0.5, s).bounds == window.bounds


def test_explicit_update_distance():
    tracker = WindowTracker(WindowConfig(n=1, k=1, update_distance=5.0), s=2.0)
    tracker.update(PoseSample(0.0, 0.0))
    assert tracker.update(PoseSample(0.0, 4.9)) is None
    assert tracker.update(PoseSample(0.0, 5.1)).sector == 2


def test_yaw_heading_source_gives_a_heading_at_start():
    tracker = WindowTracker(WindowConfig(n=1, k=2, heading_source="yaw"), s=2.0)
    w = tracker.update(PoseSample(1.0, 1.0, yaw=math.pi))
    assert w.sector == 4 and w.u_range == (-3, 1)
    # Moving +x while facing -x (reversing): yaw wins.
    assert tracker.update(PoseSample(3.0, 1.0, yaw=math.pi)).sector == 4


def test_lookahead_uses_velocity_or_motion():
    cfg = WindowConfig(n=0, k=0, lookahead_time=2.0)
    tracker = WindowTracker(cfg, s=2.0)
    # Given velocity 3 m/s along +y: centre at y = 1 + 6.
    assert tracker.update(PoseSample(1.0, 1.0, t=0.0, velocity=(0.0, 3.0))).center == (0, 3)
    tracker = WindowTracker(cfg, s=2.0)
    tracker.update(PoseSample(1.0, 1.0, t=0.0))
    # Without velocity: (5 - 1) m in 1 s = 4 m/s, so x = 5 + 8 = 13.
    assert tracker.update(PoseSample(5.0, 1.0, t=1.0)).center == (6, 0)


def test_predicted_windows_are_one_step_ahead_straight_then_the_neighbouring_sectors():
    tracker = WindowTracker(WindowConfig(n=1, k=1), s=2.0)
    tracker.update(PoseSample(0.5, 0.5))
    tracker.update(PoseSample(0.5, 2.5))  # step 2 m along +y: sector 2
    straight, left, right = tracker.predicted_windows()
    assert straight.center == left.center == right.center == (0, 2)
    assert (straight.sector, left.sector, right.sector) == (2, 3, 1)
    assert math.degrees(left.theta) == 135.0 and math.degrees(right.theta) == 45.0


def test_presets_and_bad_parameters():
    assert WindowConfig(preset="courtyard").resolved().n == 17
    assert WindowConfig(preset="courtyard").resolved().k == 10
    for bad in (
        WindowConfig(preset="moon"),
        WindowConfig(n=-1),
        WindowConfig(k=1.5),
        WindowConfig(heading_source="compass"),
        WindowConfig(update_distance=-1.0),
        WindowConfig(lookahead_time=float("nan")),
    ):
        with pytest.raises(UserError, match="window"):
            bad.resolved()


# ---------------------------------------------------------------- properties

coords = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False)
headings = st.one_of(st.none(), st.floats(min_value=-10.0, max_value=10.0, allow_nan=False))
sizes = st.sampled_from([0.5, 1.0, 2.0, 3.0, 20.0])
small = st.integers(min_value=0, max_value=6)


@given(coords, coords, headings, sizes, small, small)
def test_window_contains_the_default_square(x, y, theta, s, n, k):
    w = compute_window(x, y, theta, s, n, k)
    ci, cj = math.floor(x / s), math.floor(y / s)
    assert w.i_min <= ci - n and w.i_max >= ci + n and w.j_min <= cj - n and w.j_max >= cj + n
    assert w.center == (ci, cj)


@given(coords, coords, st.floats(min_value=-10.0, max_value=10.0, allow_nan=False), sizes, small, small)
def test_window_grows_only_toward_the_heading(x, y, theta, s, n, k):
    w = compute_window(x, y, theta, s, n, k)
    c, si = math.cos(theta), math.sin(theta)
    offsets = np.array(w.keys()) - np.array(w.center)
    u, v = offsets[:, 0], offsets[:, 1]
    # Tiles outside the square only on the side the heading points to, and by at most k.
    if (u > n).any():
        assert c > 0
    if (u < -n).any():
        assert c < 0
    if (v > n).any():
        assert si > 0
    if (v < -n).any():
        assert si < 0
    assert u.min() >= -n - k and u.max() <= n + k and v.min() >= -n - k and v.max() <= n + k
    # The dominant axis of the heading is always extended by k.
    if abs(c) >= abs(si):
        assert (u.max() if c > 0 else -u.min()) == n + k
    else:
        assert (v.max() if si > 0 else -v.min()) == n + k


@given(
    st.integers(min_value=-(10**5), max_value=10**5),
    st.integers(min_value=-(10**5), max_value=10**5),
    st.floats(min_value=0.0, max_value=0.999),
    st.floats(min_value=0.0, max_value=0.999),
    st.floats(min_value=0.0, max_value=0.999),
    st.floats(min_value=0.0, max_value=0.999),
    headings,
    sizes,
)
def test_window_is_the_same_everywhere_in_a_tile(i, j, fx1, fy1, fx2, fy2, theta, s):
    w1 = compute_window((i + fx1) * s, (j + fy1) * s, theta, s, 3, 2)
    w2 = compute_window((i + fx2) * s, (j + fy2) * s, theta, s, 3, 2)
    assert w1.bounds == w2.bounds
    assert w1.center == (i, j)


def test_lost_search_window_grows_in_steps_up_to_the_cap_and_ends_once():
    s = 2.0
    lost = LostSearchWindow(max_half_side=30.0, reach=2.0, s=s)
    wide = compute_window(5.3, 5.3, None, s, n=6, k=0)  # i, j -4..8
    assert lost.cover(SearchRegion(5.3, 5.3, 0.0, 0.0), wide, wide) is None  # 2 m rounds up to 10 m: -3..7 inside
    assert not lost.active
    home = compute_window(5.3, 5.3, None, s, n=1, k=0)  # i, j 1..3
    grown = lost.cover(SearchRegion(5.3, 5.3, 7.0, 0.0), home, home)  # 9 m rounds up to 10 m
    assert grown.bounds == (-3, 7, -3, 7) and lost.active
    assert lost.cover(SearchRegion(5.3, 5.3, 7.5, 0.0), home, grown) is None  # still 10 m: nothing new
    capped = lost.cover(SearchRegion(5.3, 5.3, 95.0, 0.0), home, grown)  # 97 m, capped at 30 m
    assert capped.bounds == (math.floor(-24.7 / s), math.floor(35.3 / s)) * 2
    assert lost.end() and not lost.active and not lost.end()
