"""The mapper interface and the map frame every mapper shares."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from robot.grid import GridSpec
from robot.world import Pose


@dataclass(frozen=True)
class MapFrame:
    """What the SLAM side is told about the map before it starts, as in the paper.

    ``grid`` is the map (size, resolution, origin); ``extent`` is the surveyed room's bounding box
    (min_x, min_y, max_x, max_y) [m] when the map size is known: nothing inside the room lies outside
    it. ``None`` for an unknown room, where the grid is a bounded area centred on the start.
    """

    grid: GridSpec
    start: Pose
    extent: tuple[float, float, float, float] | None = None

    @property
    def start_cell(self) -> tuple[int, int]:
        r, c = self.grid.world_to_index(self.start.x, self.start.y)
        return int(r), int(c)


class Evidence(NamedTuple):
    """A mapper's fine evidence grid (log-odds, > 0 occupied), for checks on what a beam may have met."""

    grid: GridSpec
    logodds: NDArray[np.float32]


class Mapper(Protocol):
    """Builds a grid from sonar sweeps taken at estimated poses."""

    name: str
    frame: MapFrame

    def integrate(self, pose: Pose, ranges_m: NDArray[np.float64]) -> None:
        """Add one sweep (ranges in sonar mounting order) taken at ``pose``."""
        ...

    def mark_body(self, pose: Pose) -> None:
        """The robot's body is at ``pose``: the space under it is free."""
        ...

    def mark_contact(self, pose: Pose, direction_rad: float) -> None:
        """The body touched something while driving towards ``direction_rad``."""
        ...

    def finalize(self) -> None:
        """Settle all evidence before the final map is read (the end of a run)."""
        ...

    def free_fraction(self) -> NDArray[np.float64]:
        """Per map cell, the share seen free; negative where something is believed occupied."""
        ...

    def states(self) -> NDArray[np.int8]:
        """The map's own belief per cell: FREE, OCCUPIED or UNKNOWN (before reachability)."""
        ...

    def evidence(self) -> Evidence | None:
        """The fine evidence grid behind the map, or None for a mapper that keeps none."""
        ...


def blocked_by_extent(frame: MapFrame) -> NDArray[np.bool_]:
    """Cells of which some area lies outside the known room extent."""
    grid = frame.grid
    out = np.zeros(grid.shape, dtype=bool)
    if frame.extent is None:
        return out
    min_x, min_y, max_x, max_y = frame.extent
    tol = 1e-6 * grid.resolution
    x0 = grid.origin_x + np.arange(grid.cols) * grid.resolution
    y0 = grid.origin_y + (grid.rows - 1 - np.arange(grid.rows)) * grid.resolution
    col_out = (x0 < min_x - tol) | (x0 + grid.resolution > max_x + tol)
    row_out = (y0 < min_y - tol) | (y0 + grid.resolution > max_y + tol)
    out |= col_out[None, :] | row_out[:, None]
    return out
