"""Ground truth (SPEC §2): blocked cells, the reachable region and the three-state truth grid."""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import NDArray

from robot.errors import WorldError
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, dilate8
from robot.world import World


def cell_boxes(grid: GridSpec) -> NDArray[np.object_]:
    """Every cell as a shapely box, shaped (rows, cols), with the same bounds as ``GridSpec.cell_bounds``."""
    rows, cols = np.indices(grid.shape)
    min_x = grid.origin_x + cols * grid.resolution
    min_y = grid.origin_y + (grid.rows - 1 - rows) * grid.resolution
    return shapely.box(min_x, min_y, min_x + grid.resolution, min_y + grid.resolution)


def blocked_cells(world: World, grid: GridSpec, rel_area_tol: float = 1e-9) -> NDArray[np.bool_]:
    """Cells any area of which lies outside the boundary or inside an obstacle (SPEC §2).

    An area counts only above ``rel_area_tol`` of a cell's area, so round-off such as a grid
    4.6000000000000005 m tall over a 4.6 m room, or a wall lying exactly on a cell edge, blocks
    nothing, while an obstacle poking 1 mm into a cell blocks it. Only cells that straddle an
    edge get an exact area computation; the rest are settled by prepared-geometry predicates.
    """
    boxes = cell_boxes(grid).ravel()
    tol_m2 = rel_area_tol * grid.resolution**2
    blocked = np.zeros(boxes.shape, dtype=bool)

    boundary = world.boundary
    shapely.prepare(boundary)
    inside = shapely.contains_properly(boundary, boxes)
    straddling = np.flatnonzero(~inside)
    if straddling.size:
        kept_m2 = shapely.area(shapely.intersection(boxes[straddling], boundary))
        outside_m2 = shapely.area(boxes[straddling]) - kept_m2
        blocked[straddling] = outside_m2 > tol_m2

    polygons = np.array([o.polygon for o in world.obstacles], dtype=object)
    if polygons.size:
        # Only cells the boundary leaves open can change; a tree finds the obstacles near each.
        open_idx = np.flatnonzero(~blocked)
        tree = shapely.STRtree(polygons)
        box_i, obstacle_i = tree.query(boxes[open_idx], predicate="intersects")
        if box_i.size:
            overlap_m2 = shapely.area(shapely.intersection(boxes[open_idx[box_i]], polygons[obstacle_i]))
            hit = open_idx[box_i[overlap_m2 > tol_m2]]
            blocked[hit] = True
    return blocked.reshape(grid.shape)


def _spread_along_rows(open_cells: NDArray[np.bool_], reached: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Extend ``reached`` to the whole horizontal run of open cells it touches."""
    rows, cols = open_cells.shape
    left_open = np.zeros_like(open_cells)
    left_open[:, 1:] = open_cells[:, :-1]
    run_start = open_cells & ~left_open
    run_id = np.cumsum(run_start.ravel()).reshape(rows, cols) * open_cells  # 0 = blocked
    hit = np.zeros(int(run_id.max()) + 1, dtype=bool)
    hit[run_id[reached & open_cells]] = True
    hit[0] = False
    return hit[run_id]


def reachable_cells(blocked: NDArray[np.bool_], start_row: int, start_col: int) -> NDArray[np.bool_]:
    """Unblocked cells 8-connected to the start cell, a diagonal step needing both orthogonal neighbours open.

    With that diagonal rule every allowed diagonal step can be replaced by two orthogonal ones, so
    the region equals the 4-connected component of the start. It is grown by whole row and column
    runs at a time, so the number of sweeps is the number of turns a path needs, not its length.
    A blocked (or out-of-range) start cell reaches nothing.
    """
    blocked = np.asarray(blocked, dtype=bool)
    if blocked.ndim != 2:
        raise ValueError(f"blocked must be a 2-D array, got shape {blocked.shape}")
    rows, cols = blocked.shape
    reached = np.zeros_like(blocked)
    if not (0 <= start_row < rows and 0 <= start_col < cols) or blocked[start_row, start_col]:
        return reached
    open_cells = ~blocked
    reached[start_row, start_col] = True
    count = 1
    while True:
        reached = _spread_along_rows(open_cells, reached)
        reached = _spread_along_rows(open_cells.T, reached.T).T
        new_count = int(reached.sum())
        if new_count == count:
            return reached
        count = new_count


def truth_states(blocked: NDArray[np.bool_], reachable: NDArray[np.bool_]) -> NDArray[np.int8]:
    """White = reachable, black = blocked and 8-adjacent to a reachable cell, grey = the rest."""
    states = np.full(blocked.shape, UNKNOWN, dtype=np.int8)
    states[blocked & dilate8(reachable)] = OCCUPIED
    states[reachable] = FREE
    return states


def start_cell(world: World, grid: GridSpec) -> tuple[int, int]:
    """(row, col) of the cell holding the world's true start position."""
    row, col = grid.world_to_index(world.start.x, world.start.y)
    return int(row), int(col)


def truth_grid(world: World, resolution: float) -> tuple[GridSpec, NDArray[np.int8]]:
    """The world's grid and its ground-truth states (SPEC §2).

    Raises WorldError when the start cell itself is blocked at this resolution (the start is
    too close to a wall for cells this coarse), because the truth would then have no free cell.
    """
    if not resolution > 0:
        raise WorldError(f"{world.source or world.name}: resolution must be positive, got {resolution}")
    grid = world.grid(resolution)
    blocked = blocked_cells(world, grid)
    row, col = start_cell(world, grid)
    if blocked[row, col]:
        raise WorldError(
            f"{world.source or world.name}: start: the start cell (row {row}, col {col}) is blocked "
            f"at resolution {resolution} m; use a finer resolution or move the start"
        )
    return grid, truth_states(blocked, reachable_cells(blocked, row, col))
