"""Tile geometry against closed-form answers."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiles.grid import (
    check_grid_size,
    parse_tile_stem,
    tile_center,
    tile_filename,
    tile_index,
    tile_stem,
)


def test_index_at_cell_boundaries_and_negative_coordinates():
    xs = np.array([0.0, 1.999999, 2.0, -1e-12, -2.0, -2.000001])
    np.testing.assert_array_equal(tile_index(xs, 2.0), [0, 0, 1, -1, -1, -2])


def test_index_with_grid_size_not_a_power_of_two():
    # s = 0.3: 0.9 / 0.3 is 3.0000000000000004 in float64, still tile 3; 0.6 / 0.3 is exactly 2.
    assert tile_index(0.9, 0.3) == 3
    assert tile_index(0.6, 0.3) == 2
    assert tile_index(-0.1, 0.3) == -1


def test_utm_size_coordinates_stay_exact():
    y = 5_400_000.25  # float64 holds it exactly
    assert tile_index(y, 2.0) == 2_700_000
    assert tile_center(2_700_000, 2.0) == 5_400_001.0
    assert tile_stem(250_000, 2_700_000, 2.0) == "500001.0_5400001.0"


def test_center_matches_paper_equation():
    for x in (-7.3, -0.5, 0.0, 0.5, 3.9, 1234.5):
        s = 2.0
        assert tile_center(tile_index(x, s), s) == math.floor(x / s) * s + s / 2


@pytest.mark.parametrize(
    ("i", "j", "s", "name"),
    [
        (0, -2, 2.0, "1.0_-3.0.pcd"),
        (0, -2, 0.5, "0.25_-0.75.pcd"),
        (1, 0, 0.2, "0.3_0.1.pcd"),
        (-1, 3, 20.0, "-10.0_70.0.pcd"),
    ],
)
def test_file_names(i, j, s, name):
    assert tile_filename(i, j, s) == name


@given(
    st.integers(min_value=-(10**7), max_value=10**7),
    st.integers(min_value=-(10**7), max_value=10**7),
    st.sampled_from([0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 2.5, 7.0, 20.0, 25.0, 1 / 3]),
)
def test_stem_round_trips_exactly(i, j, s):
    assert parse_tile_stem(tile_stem(i, j, s), s) == (i, j)


@pytest.mark.parametrize("stem", ["1_3", "map", "1.0-3.0", "1.0_3.0_5.0", "2.0_3.0", "1e3_1.0"])
def test_bad_stems_are_rejected(stem):
    with pytest.raises(ValueError):
        parse_tile_stem(stem, 2.0)


@pytest.mark.parametrize("s", [0, -2, float("nan"), float("inf")])
def test_bad_grid_size_is_a_user_error(s):
    with pytest.raises(UserError, match="grid size"):
        check_grid_size(s)
