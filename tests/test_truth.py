"""Ground truth (SPEC §2): blocked cells, reachability with the diagonal rule, and truth states."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from robot.errors import WorldError
from robot.grid import FREE, OCCUPIED, UNKNOWN
from robot.truth import blocked_cells, cell_boxes, reachable_cells, truth_grid, truth_states
from robot.world import World, builtin_worlds, load_world, world_from_dict

B, W, G = int(OCCUPIED), int(FREE), int(UNKNOWN)


def rect(x0: float, y0: float, x1: float, y1: float) -> dict[str, object]:
    """An axis-aligned rect obstacle given by its corners [m]."""
    return {"shape": "rect", "center": [(x0 + x1) / 2, (y0 + y1) / 2], "size": [x1 - x0, y1 - y0]}


def room(width: float, height: float, start: tuple[float, float], *obstacles: dict[str, object]) -> World:
    return world_from_dict(
        {
            "boundary": [[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]],
            "start": {"x": start[0], "y": start[1], "theta_deg": 0.0},
            "obstacles": list(obstacles),
        },
        "test.toml",
    )


def test_walls_on_cell_edges_block_nothing() -> None:
    grid, states = truth_grid(room(1.0, 0.6, (0.1, 0.1)), 0.2)
    assert grid.shape == (3, 5)
    assert (states == FREE).all()


def test_obstacle_exactly_on_cell_edges_blocks_only_its_own_cell() -> None:
    _, states = truth_grid(room(1.0, 0.6, (0.1, 0.1), rect(0.6, 0.4, 0.8, 0.6)), 0.2)
    expected = [
        [W, W, W, B, W],
        [W, W, W, W, W],
        [W, W, W, W, W],
    ]
    np.testing.assert_array_equal(states, expected)


def test_obstacle_poking_one_millimetre_into_a_cell_blocks_it() -> None:
    wider = room(1.0, 0.6, (0.1, 0.1), rect(0.599, 0.4, 0.801, 0.6))
    _, states = truth_grid(wider, 0.2)
    np.testing.assert_array_equal(states[0], [W, W, B, B, B])
    np.testing.assert_array_equal(states[1:], np.zeros((2, 5)))

    lower = room(1.0, 0.6, (0.1, 0.1), rect(0.6, 0.399, 0.8, 0.6))
    _, states = truth_grid(lower, 0.2)
    np.testing.assert_array_equal(states[:, 3], [B, B, W])


def test_one_millimetre_corner_overlap_blocks_the_cell() -> None:
    world = room(1.0, 0.6, (0.1, 0.1), rect(0.799, 0.599 - 0.2, 0.999, 0.599))
    blocked = blocked_cells(world, world.grid(0.2))
    expected = np.zeros((3, 5), dtype=bool)
    expected[0:2, 3:5] = True  # cell (1, 3) holds only a 1 mm x 1 mm corner of the obstacle
    np.testing.assert_array_equal(blocked, expected)


def test_boundary_not_a_multiple_of_the_resolution_blocks_the_partial_column_only() -> None:
    # room1 is 3.29 x 4.6 m: 23 rows (4.6 / 0.2 = 22.999999999999996) and 17 columns, the last one partial.
    grid, states = truth_grid(load_world("room1"), 0.2)
    assert grid.shape == (23, 17)
    assert (states[:, :16] == FREE).all()
    assert (states[:, 16] == OCCUPIED).all()


@pytest.mark.parametrize(
    ("name", "rows", "cols"), [("room1", 23, 17), ("room2", 16, 16), ("room3", 22, 17), ("room4", 23, 16)]
)
def test_paper_room_grid_sizes_at_20_cm(name: str, rows: int, cols: int) -> None:
    grid, states = truth_grid(load_world(name), 0.2)
    assert (grid.rows, grid.cols) == (rows, cols)
    assert states.shape == (rows, cols)
    assert grid.total_cells == {"room1": 391, "room2": 256, "room3": 374, "room4": 368}[name]


def test_two_blocked_orthogonal_neighbours_stop_a_diagonal_step() -> None:
    # 3 x 3 room, start bottom-left; the cells above and right of it are blocked.
    world = room(0.6, 0.6, (0.1, 0.1), rect(0.0, 0.2, 0.2, 0.4), rect(0.2, 0.0, 0.4, 0.2))
    _, states = truth_grid(world, 0.2)
    expected = [
        [G, G, G],
        [B, G, G],
        [W, B, G],
    ]
    np.testing.assert_array_equal(states, expected)


def test_one_open_orthogonal_neighbour_lets_the_region_round_the_corner() -> None:
    world = room(0.6, 0.6, (0.1, 0.1), rect(0.0, 0.2, 0.2, 0.4))
    _, states = truth_grid(world, 0.2)
    expected = [
        [W, W, W],
        [B, W, W],
        [W, W, W],
    ]
    np.testing.assert_array_equal(states, expected)


def test_reachable_cells_on_plain_arrays() -> None:
    diagonal_gap = np.array([[0, 1], [1, 0]], dtype=bool)
    np.testing.assert_array_equal(reachable_cells(diagonal_gap, 0, 0), [[True, False], [False, False]])
    np.testing.assert_array_equal(reachable_cells(diagonal_gap, 0, 1), np.zeros((2, 2), dtype=bool))
    np.testing.assert_array_equal(reachable_cells(diagonal_gap, 5, 5), np.zeros((2, 2), dtype=bool))


def test_reachable_cells_follows_a_winding_corridor() -> None:
    # A serpentine: open rows joined alternately at the right and left ends.
    blocked = np.zeros((7, 6), dtype=bool)
    blocked[1, :5] = True
    blocked[3, 1:] = True
    blocked[5, :5] = True
    np.testing.assert_array_equal(reachable_cells(blocked, 0, 0), ~blocked)
    np.testing.assert_array_equal(reachable_cells(blocked, 6, 0), ~blocked)


def test_truth_states_marks_blocked_cells_next_to_reachable_ones_black_including_diagonals() -> None:
    blocked = np.ones((4, 4), dtype=bool)
    blocked[1, 1] = False
    reachable = np.zeros((4, 4), dtype=bool)
    reachable[1, 1] = True
    expected = [
        [B, B, B, G],
        [B, W, B, G],
        [B, B, B, G],
        [G, G, G, G],
    ]
    np.testing.assert_array_equal(truth_states(blocked, reachable), expected)


def test_enclosed_hollow_is_grey() -> None:
    # A closed 0.6 m box with 0.2 m walls in a 1.4 x 1.4 m room: its one-cell hollow is unreachable.
    walls = [rect(0.4, 0.4, 1.0, 0.6), rect(0.4, 0.8, 1.0, 1.0), rect(0.4, 0.6, 0.6, 0.8), rect(0.8, 0.6, 1.0, 0.8)]
    _, states = truth_grid(room(1.4, 1.4, (0.1, 0.1), *walls), 0.2)
    expected = np.full((7, 7), W)
    expected[2:5, 2:5] = B
    expected[3, 3] = G
    np.testing.assert_array_equal(states, expected)


@pytest.mark.parametrize("name", sorted(builtin_worlds()))
def test_vectorised_blocked_cells_match_a_cell_by_cell_reference(name: str) -> None:
    world = load_world(name)
    grid = world.grid(0.25)
    free = world.free_space
    boxes = cell_boxes(grid)
    outside_m2 = np.vectorize(lambda box: shapely.difference(box, free).area)(boxes)
    np.testing.assert_array_equal(blocked_cells(world, grid), outside_m2 > 1e-9 * grid.resolution**2)


@pytest.mark.parametrize("name", sorted(builtin_worlds()))
def test_builtin_truth_is_consistent(name: str) -> None:
    world = load_world(name)
    grid, states = truth_grid(world, 0.1)
    row, col = grid.world_to_index(world.start.x, world.start.y)
    assert states[row, col] == FREE
    assert set(np.unique(states).tolist()) <= {G, W, B}
    blocked = blocked_cells(world, grid)
    assert not (blocked & (states == FREE)).any()
    assert blocked[states == OCCUPIED].all()
    # A grey cell never shares an edge with a white one (it would have been reached).
    white = states == FREE
    grey = states == UNKNOWN
    assert not (white[1:] & grey[:-1]).any() and not (white[:-1] & grey[1:]).any()
    assert not (white[:, 1:] & grey[:, :-1]).any() and not (white[:, :-1] & grey[:, 1:]).any()


def test_blocked_start_cell_is_a_world_error() -> None:
    # At 0.4 m the right-hand column (0.8 .. 1.2 m) pokes out of a 1.0 m room.
    with pytest.raises(WorldError, match=r"test\.toml: start: .*blocked at resolution 0\.4"):
        truth_grid(room(1.0, 0.6, (0.9, 0.1)), 0.4)
