"""Grid geometry: the one place where world coordinates and grid indices are converted.

Arrays are indexed ``[row, col]`` in export orientation: row 0 holds the largest y,
column 0 the smallest x (SPEC §2). Cell states use the paper's codes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

UNKNOWN = np.int8(-1)  # grey: unknown or inaccessible
FREE = np.int8(0)  # white
OCCUPIED = np.int8(1)  # black

# Tolerance for floating-point sizes such as 4.6 / 0.2 = 22.999999999999996 [cells].
_CEIL_TOL = 1e-9


def cells_to_cover(length_m: float, resolution_m: float) -> int:
    """Number of cells of ``resolution_m`` needed to cover ``length_m`` (at least one)."""
    return max(1, math.ceil(length_m / resolution_m - _CEIL_TOL))


@dataclass(frozen=True)
class GridSpec:
    """A rectangular grid: origin is the minimum (x, y) corner in metres."""

    origin_x: float  # [m]
    origin_y: float  # [m]
    resolution: float  # cell side [m]
    rows: int
    cols: int

    @classmethod
    def covering(cls, min_x: float, min_y: float, max_x: float, max_y: float, resolution: float) -> GridSpec:
        """The grid whose origin is (min_x, min_y) and which covers the box."""
        return cls(
            origin_x=min_x,
            origin_y=min_y,
            resolution=resolution,
            rows=cells_to_cover(max_y - min_y, resolution),
            cols=cells_to_cover(max_x - min_x, resolution),
        )

    @property
    def shape(self) -> tuple[int, int]:
        return (self.rows, self.cols)

    @property
    def total_cells(self) -> int:
        return self.rows * self.cols

    @property
    def width_m(self) -> float:
        return self.cols * self.resolution

    @property
    def height_m(self) -> float:
        return self.rows * self.resolution

    def world_to_index(
        self, x: NDArray[np.float64] | float, y: NDArray[np.float64] | float
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(row, col) of the cells containing points; points outside give out-of-range indices."""
        col = np.floor((np.asarray(x, dtype=float) - self.origin_x) / self.resolution).astype(np.int64)
        iy = np.floor((np.asarray(y, dtype=float) - self.origin_y) / self.resolution).astype(np.int64)
        return self.rows - 1 - iy, col

    def point_index(self, x: float, y: float) -> tuple[int, int]:
        """``world_to_index`` for one point, on plain floats (the same arithmetic, without numpy's
        per-call cost: hot paths ask for single points)."""
        col = math.floor((x - self.origin_x) / self.resolution)
        return self.rows - 1 - math.floor((y - self.origin_y) / self.resolution), col

    def index_to_world(
        self, row: NDArray[np.int64] | int, col: NDArray[np.int64] | int
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World (x, y) of cell centres."""
        r = np.asarray(row, dtype=float)
        c = np.asarray(col, dtype=float)
        x = self.origin_x + (c + 0.5) * self.resolution
        y = self.origin_y + (self.rows - r - 0.5) * self.resolution
        return x, y

    def cell_bounds(self, row: int, col: int) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) of one cell [m]."""
        min_x = self.origin_x + col * self.resolution
        min_y = self.origin_y + (self.rows - 1 - row) * self.resolution
        return (min_x, min_y, min_x + self.resolution, min_y + self.resolution)

    def contains_index(self, row: NDArray[np.int64] | int, col: NDArray[np.int64] | int) -> NDArray[np.bool_]:
        r = np.asarray(row)
        c = np.asarray(col)
        return (r >= 0) & (r < self.rows) & (c >= 0) & (c < self.cols)

    def centers(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World x and y of every cell centre, each shaped (rows, cols)."""
        rows, cols = np.indices(self.shape)
        return self.index_to_world(rows, cols)

    def empty(self) -> NDArray[np.int8]:
        """An all-grey state grid."""
        return np.full(self.shape, UNKNOWN, dtype=np.int8)


def lone_occupied(states: NDArray[np.int8]) -> NDArray[np.bool_]:
    """Occupied cells whose eight neighbours are all free (cells off the grid count as not free):
    a chair leg, or a stray echo that sweeps from elsewhere would clear."""
    rows, cols = states.shape
    not_free = np.ones((rows + 2, cols + 2), dtype=bool)
    not_free[1:-1, 1:-1] = states != FREE
    neighbours = np.zeros((rows, cols), dtype=bool)
    for dr in range(3):
        for dc in range(3):
            if dr != 1 or dc != 1:
                neighbours |= not_free[dr : dr + rows, dc : dc + cols]
    return (states == OCCUPIED) & ~neighbours


def dilate8(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``mask`` grown by one cell in all eight directions."""
    rows, cols = mask.shape
    padded = np.zeros((rows + 2, cols + 2), dtype=bool)
    padded[1:-1, 1:-1] = mask
    out = np.zeros_like(mask)
    for dr in range(3):
        for dc in range(3):
            out |= padded[dr : dr + rows, dc : dc + cols]
    return out
