"""Grid geometry (SPEC §2): sizes, and world <-> index conversion at index 0 and at the last cell."""

from __future__ import annotations

import numpy as np
import pytest

from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, cells_to_cover

# A grid away from the world origin, so that origin mistakes show: 5 cols x 3 rows of 0.2 m.
GRID = GridSpec(origin_x=-1.3, origin_y=2.7, resolution=0.2, rows=3, cols=5)


def test_state_codes_are_the_papers() -> None:
    assert (int(UNKNOWN), int(FREE), int(OCCUPIED)) == (-1, 0, 1)
    empty = GRID.empty()
    assert empty.dtype == np.int8 and empty.shape == (3, 5) and (empty == UNKNOWN).all()


@pytest.mark.parametrize(
    ("length_m", "resolution_m", "cells"),
    [
        (4.6, 0.2, 23),
        (3.29, 0.2, 17),
        (3.05, 0.2, 16),
        (3.15, 0.2, 16),
        (4.32, 0.2, 22),
        (4.59, 0.2, 23),
        (1.0, 0.2, 5),
        (0.6, 0.2, 3),
        (0.6000001, 0.2, 4),
        (0.0, 0.2, 1),
        (0.05, 0.2, 1),
    ],
)
def test_cells_to_cover(length_m: float, resolution_m: float, cells: int) -> None:
    assert cells_to_cover(length_m, resolution_m) == cells


def test_covering_puts_the_origin_at_the_minimum_corner() -> None:
    grid = GridSpec.covering(-1.0, 0.5, 2.29, 5.1, 0.2)
    assert (grid.origin_x, grid.origin_y) == (-1.0, 0.5)
    assert grid.shape == (23, 17)
    assert grid.total_cells == 391
    assert grid.width_m == pytest.approx(3.4) and grid.height_m == pytest.approx(4.6)


def test_the_origin_is_in_the_bottom_left_cell() -> None:
    row, col = GRID.world_to_index(-1.3, 2.7)
    assert (int(row), int(col)) == (2, 0)  # last row (smallest y), first column (smallest x)


def test_a_point_just_inside_the_max_corner_is_in_the_top_right_cell() -> None:
    max_x = GRID.origin_x + GRID.width_m
    max_y = GRID.origin_y + GRID.height_m
    row, col = GRID.world_to_index(max_x - 1e-9, max_y - 1e-9)
    assert (int(row), int(col)) == (0, 4)


def test_the_max_edges_belong_to_no_cell() -> None:
    row, col = GRID.world_to_index(GRID.origin_x + GRID.width_m, GRID.origin_y + GRID.height_m)
    assert (int(row), int(col)) == (-1, 5)
    assert not GRID.contains_index(row, col)


def test_index_to_world_gives_cell_centres_at_both_ends() -> None:
    x, y = GRID.index_to_world(0, 0)  # top-left
    assert (float(x), float(y)) == pytest.approx((-1.2, 3.2))
    x, y = GRID.index_to_world(2, 4)  # bottom-right
    assert (float(x), float(y)) == pytest.approx((-0.4, 2.8))


def test_round_trip_over_every_cell() -> None:
    grid = GridSpec.covering(0.0, 0.0, 3.29, 4.6, 0.2)
    rows, cols = np.indices(grid.shape)
    x, y = grid.index_to_world(rows, cols)
    back_row, back_col = grid.world_to_index(x, y)
    np.testing.assert_array_equal(back_row, rows)
    np.testing.assert_array_equal(back_col, cols)
    assert grid.contains_index(back_row, back_col).all()


def test_cell_bounds_surround_the_centre_and_tile_the_grid() -> None:
    assert GRID.cell_bounds(2, 0) == pytest.approx((-1.3, 2.7, -1.1, 2.9))
    assert GRID.cell_bounds(0, 4) == pytest.approx((-0.5, 3.1, -0.3, 3.3))
    for row, col in [(0, 0), (1, 3), (2, 4)]:
        min_x, min_y, max_x, max_y = GRID.cell_bounds(row, col)
        x, y = GRID.index_to_world(row, col)
        assert (float(x), float(y)) == pytest.approx(((min_x + max_x) / 2, (min_y + max_y) / 2))


def test_centers_are_shaped_like_the_grid_with_y_decreasing_down_the_rows() -> None:
    x, y = GRID.centers()
    assert x.shape == y.shape == (3, 5)
    assert (np.diff(x, axis=1) > 0).all() and (np.diff(y, axis=0) < 0).all()


def test_points_outside_give_out_of_range_indices() -> None:
    row, col = GRID.world_to_index(np.array([-1.31, -1.0, 0.0]), np.array([3.0, 2.69, 3.0]))
    np.testing.assert_array_equal(GRID.contains_index(row, col), [False, False, False])
    assert int(col[0]) == -1 and int(row[1]) == 3 and int(col[2]) == 6
