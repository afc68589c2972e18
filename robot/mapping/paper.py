"""The paper's mapper: the echo's arc is occupied, the cone before it is free, arcs from different
vantage points keep only their overlap, and a cell once found free is never marked occupied again.
Works directly on the map grid, as the paper does."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig
from robot.grid import FREE, OCCUPIED, UNKNOWN
from robot.mapping.base import Evidence, MapFrame, blocked_by_extent
from robot.mapping.geometry import cone_cells, place_beams
from robot.world import Pose


class PaperMapper:
    name = "paper"

    def __init__(self, frame: MapFrame, robot: RobotConfig) -> None:
        self.frame = frame
        self.robot = robot
        grid = frame.grid
        self._state = np.full(grid.shape, UNKNOWN, dtype=np.int8)
        self._arc_id = np.zeros(grid.shape, dtype=np.int64)  # which arc made a cell occupied (0 = none)
        self._arc_vantage: dict[int, tuple[int, int]] = {}
        self._next_arc = 1
        self._half = math.radians(robot.sonar.beam_width_deg) / 2.0
        self._outside = blocked_by_extent(frame)

    def _vantage(self, pose: Pose) -> tuple[int, int]:
        r, c = self.frame.grid.world_to_index(pose.x, pose.y)
        return int(r), int(c)

    def integrate(self, pose: Pose, ranges_m: NDArray[np.float64]) -> None:
        grid = self.frame.grid
        half_cell = grid.resolution / 2.0
        vantage = self._vantage(pose)
        for beam in place_beams(pose, ranges_m, self.robot):
            if not beam.echo:
                continue
            cells = cone_cells(grid, beam, self._half, beam.range_m + half_cell)
            if cells.rows.size == 0:
                continue
            before = cells.dist_m < beam.range_m - half_cell
            self._state[cells.rows[before], cells.cols[before]] = FREE
            self._arc_id[cells.rows[before], cells.cols[before]] = 0
            on_arc = ~before
            rows, cols = cells.rows[on_arc], cells.cols[on_arc]
            candidate = self._state[rows, cols] != FREE
            rows, cols = rows[candidate], cols[candidate]
            if rows.size == 0:
                continue
            ids = self._arc_id[rows, cols]
            other = np.unique(ids[(ids > 0)])
            other = np.array([i for i in other if self._arc_vantage.get(int(i)) != vantage], dtype=np.int64)
            if other.size:
                # Overlap with arcs seen from elsewhere: only the overlap stays occupied.
                overlap = np.isin(ids, other)
                for arc in other:
                    gone = (self._arc_id == arc) & (self._state == OCCUPIED)
                    gone[rows[overlap], cols[overlap]] = False
                    self._state[gone] = FREE
                    self._arc_id[gone] = 0
                arc_id = self._next_arc
                self._arc_id[rows[overlap], cols[overlap]] = arc_id
            else:
                arc_id = self._next_arc
                self._state[rows, cols] = OCCUPIED
                self._arc_id[rows, cols] = arc_id
            self._arc_vantage[arc_id] = vantage
            self._next_arc += 1

    def mark_body(self, pose: Pose) -> None:
        r, c = self._vantage(pose)
        if self.frame.grid.contains_index(r, c):
            self._state[r, c] = FREE
            self._arc_id[r, c] = 0

    def mark_contact(self, pose: Pose, direction_rad: float) -> None:
        d = self.robot.radius_m + 0.01
        r, c = self.frame.grid.world_to_index(
            pose.x + d * math.cos(direction_rad), pose.y + d * math.sin(direction_rad)
        )
        if self.frame.grid.contains_index(r, c) and self._state[int(r), int(c)] != FREE:
            self._state[int(r), int(c)] = OCCUPIED

    def finalize(self) -> None:
        """The paper's rule is already final after every reading."""

    def free_fraction(self) -> NDArray[np.float64]:
        states = self.states()
        return np.where(states == OCCUPIED, -1.0, (states == FREE).astype(float))

    def states(self) -> NDArray[np.int8]:
        out = self._state.copy()
        out[self._outside] = OCCUPIED
        return out

    def evidence(self) -> Evidence | None:
        return None  # the paper's rule keeps cell states only
