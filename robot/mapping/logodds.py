"""The probabilistic mapper: log-odds evidence on a fine grid with an inverse sonar model.

Starts from Moravec & Elfes (1985) and Thrun (Probabilistic Robotics ch. 9), adapted to what sonar
gets wrong:
- the cone before an echo is free, with weight falling off towards the cone's edge and with range,
  where specular misses hide glancing surfaces;
- the echo's arc is occupied "somewhere": the evidence goes to the arc cells in proportion to how
  likely each still is to be occupied (cells already known free get little), so repeated views
  from different vantage points concentrate it on the real surface;
- a no-echo reading clears at most a short stretch, since it is often a specular miss;
- the robot's body clears the cells under it.
Evidence lives on a fine grid (a few centimetres); a map cell is black if any fine cell in it is
occupied and white only if all of it is free, which keeps white cells safe.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from robot.mapping.base import MapFrame, blocked_by_extent
from robot.mapping.geometry import ConeCells, cone_cells, place_beams
from robot.world import Pose


class LogOddsParams(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    fine_cell_m: float = Field(default=0.05, gt=0.005, le=0.5)  # evidence grid cell [m]
    l_free: float = Field(default=-0.7, lt=0.0)  # per reading, on the axis, near
    l_occ: float = Field(default=0.6, gt=0.0)  # per echo, to its most likely arc cell
    l_body: float = Field(default=-3.0, lt=0.0)  # cells under the robot
    l_contact: float = Field(default=3.0, gt=0.0)  # a bump
    l_clamp: float = Field(default=6.0, gt=0.0)
    occ_threshold: float = Field(default=0.8, gt=0.0)
    free_threshold: float = Field(default=-0.65, lt=0.0)
    free_margin_m: float = Field(default=0.012, ge=0.0)  # carve up to this short of the echo ...
    free_margin_frac: float = Field(default=0.01, ge=0.0)  # ... plus this share of the range
    carve_full_m: float = Field(default=0.8, gt=0.0)  # full free weight up to here ...
    carve_max_m: float = Field(default=2.0, gt=0.0)  # ... fading to zero here
    no_echo_carve_m: float = Field(default=1.0, ge=0.0)  # how far a no-echo reading clears ...
    no_echo_weight: float = Field(default=0.5, ge=0.0, le=1.0)  # ... and how strongly
    max_echo_range_m: float = Field(default=2.0, gt=0.0)  # echoes beyond this are not mapped
    occ_full_m: float = Field(default=0.6, gt=0.0)  # full occupied weight up to here, then fading
    occ_far_weight: float = Field(default=0.3, ge=0.0, le=1.0)  # ... to this at max_echo_range_m
    extent_snap_m: float = Field(default=0.03, ge=0.0)  # echoes this close inside the room box are its wall
    free_edge_weight: float = Field(default=0.5, ge=0.0, le=1.0)  # free weight at the cone edge
    arc_edge_weight: float = Field(default=0.6, ge=0.0, le=1.0)  # occupied prior at the cone edge


class LogOddsMapper:
    name = "logodds"

    def __init__(self, frame: MapFrame, robot: RobotConfig, params: LogOddsParams | None = None) -> None:
        self.frame = frame
        self.robot = robot
        self.params = p = params or LogOddsParams()
        grid = frame.grid
        self.k = max(1, round(grid.resolution / p.fine_cell_m))
        self.fine = GridSpec(
            grid.origin_x, grid.origin_y, grid.resolution / self.k, grid.rows * self.k, grid.cols * self.k
        )
        self.logodds = np.zeros(self.fine.shape, dtype=np.float32)
        self._half = math.radians(robot.sonar.beam_width_deg) / 2.0
        self._outside = blocked_by_extent(frame)
        if frame.extent is not None:
            self._fine_outside = self._fine_outside_extent(frame.extent, 0.0)
            self._near_extent = self._fine_outside_extent(frame.extent, p.extent_snap_m)
        else:
            self._fine_outside = np.zeros(self.fine.shape, dtype=bool)
            self._near_extent = self._fine_outside

    def _fine_outside_extent(self, extent: tuple[float, float, float, float], margin_m: float) -> NDArray[np.bool_]:
        """Fine cells whose centre lies outside the room box shrunk by ``margin_m``."""
        xs, ys = self.fine.centers()
        min_x, min_y, max_x, max_y = extent
        m = margin_m
        return (xs < min_x + m) | (xs > max_x - m) | (ys < min_y + m) | (ys > max_y - m)

    # -- evidence ----------------------------------------------------------------------------
    def integrate(self, pose: Pose, ranges_m: NDArray[np.float64]) -> None:
        p = self.params
        L = self.logodds
        half = self._half
        for beam in place_beams(pose, ranges_m, self.robot):
            r = beam.range_m
            if beam.echo and r <= p.max_echo_range_m:
                free_to = r - p.free_margin_m - p.free_margin_frac * r
                reach = r + self.fine.resolution
            else:
                free_to = min(p.no_echo_carve_m, r)
                reach = free_to
            reach = min(reach, p.carve_max_m + self.fine.resolution) if not beam.echo else reach
            cells = cone_cells(self.fine, beam, half, reach)
            if cells.rows.size == 0:
                continue
            ang = (cells.off_axis_rad / half) ** 2
            free = cells.dist_m < free_to
            free &= ~self._occluded(cells, L, free_to)
            if np.any(free):
                d = cells.dist_m[free]
                fall = np.clip((p.carve_max_m - d) / max(p.carve_max_m - p.carve_full_m, 1e-9), 0.0, 1.0)
                w = (1.0 - (1.0 - p.free_edge_weight) * ang[free]) * fall
                if not beam.echo:
                    w = w * p.no_echo_weight
                np.add.at(L, (cells.rows[free], cells.cols[free]), p.l_free * w)
            if not (beam.echo and r <= p.max_echo_range_m):
                continue
            # The surface is at r; the occupied cell is the one just behind it.
            arc = (cells.dist_m >= r) & (cells.dist_m < r + self.fine.resolution)
            rows, cols = cells.rows[arc], cells.cols[arc]
            prior = 1.0 - (1.0 - p.arc_edge_weight) * ang[arc]
            ax = beam.x + (r + 0.5 * self.fine.resolution) * math.cos(beam.axis_rad)
            ay = beam.y + (r + 0.5 * self.fine.resolution) * math.sin(beam.axis_rad)
            ar, ac = self.fine.world_to_index(ax, ay)
            if self.fine.contains_index(ar, ac):
                rows = np.append(rows, int(ar))
                cols = np.append(cols, int(ac))
                prior = np.append(prior, 1.0)
            if rows.size == 0:
                continue
            keep = ~self._fine_outside[rows, cols] & ~self._near_extent[rows, cols]
            rows, cols, prior = rows[keep], cols[keep], prior[keep]
            if rows.size == 0:
                continue
            p_occ = 1.0 / (1.0 + np.exp(-L[rows, cols].astype(np.float64)))
            w = prior * p_occ
            if w.max() <= 0:
                continue
            span = max(p.max_echo_range_m - p.occ_full_m, 1e-9)
            near = float(np.clip((p.max_echo_range_m - r) / span, 0.0, 1.0))
            strength = p.occ_far_weight + (1.0 - p.occ_far_weight) * near
            np.add.at(L, (rows, cols), p.l_occ * strength * w / w.max())
        np.clip(L, -p.l_clamp, p.l_clamp, out=L)

    def _occluded(self, cells: ConeCells, L: NDArray[np.float32], free_to: float) -> NDArray[np.bool_]:
        """Cone cells at or behind a cell already believed occupied.

        A sonar cannot see through a solid object, so a reading that runs past a known obstacle in
        its cone (it missed it at a glancing angle, or the obstacle is off to the side) says nothing
        about the space behind it.
        """
        occ = (L[cells.rows, cells.cols] >= self.params.occ_threshold) & (cells.dist_m < free_to)
        if not np.any(occ):
            return occ
        occ_d = cells.dist_m[occ]
        occ_a = cells.off_axis_rad[occ]
        half_width = np.arctan2(0.75 * self.fine.resolution, occ_d)  # angular half-size of a cell
        behind = (cells.dist_m[:, None] >= occ_d[None, :] - 1e-9) & (
            np.abs(cells.off_axis_rad[:, None] - occ_a[None, :]) <= half_width[None, :]
        )
        return np.any(behind, axis=1)

    def _disk(self, x: float, y: float, radius: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        f = self.fine
        r0, c0 = f.world_to_index(x + radius, y + radius)
        r1, c1 = f.world_to_index(x - radius, y - radius)
        rows = np.arange(max(int(r0), 0), min(int(r1), f.rows - 1) + 1)
        cols = np.arange(max(int(c1), 0), min(int(c0), f.cols - 1) + 1)
        if rows.size == 0 or cols.size == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        rr, cc = np.meshgrid(rows, cols, indexing="ij")
        cx, cy = f.index_to_world(rr, cc)
        inside = np.hypot(cx - x, cy - y) <= radius
        return rr[inside], cc[inside]

    def mark_body(self, pose: Pose) -> None:
        rows, cols = self._disk(pose.x, pose.y, self.robot.radius_m)
        L = self.logodds
        L[rows, cols] = np.minimum(L[rows, cols] + self.params.l_body, L[rows, cols])
        np.clip(L, -self.params.l_clamp, self.params.l_clamp, out=L)

    def mark_contact(self, pose: Pose, direction_rad: float) -> None:
        d = self.robot.radius_m + 0.5 * self.fine.resolution
        r, c = self.fine.world_to_index(pose.x + d * math.cos(direction_rad), pose.y + d * math.sin(direction_rad))
        if self.fine.contains_index(r, c):
            self.logodds[int(r), int(c)] = min(
                self.logodds[int(r), int(c)] + self.params.l_contact, self.params.l_clamp
            )

    # -- belief -------------------------------------------------------------------------------
    def fine_states(self) -> NDArray[np.int8]:
        p = self.params
        out = np.full(self.fine.shape, UNKNOWN, dtype=np.int8)
        out[self.logodds >= p.occ_threshold] = OCCUPIED
        out[self.logodds <= p.free_threshold] = FREE
        return out

    def passable(self, min_free_fraction: float = 0.25) -> NDArray[np.bool_]:
        """Map cells the robot may drive into: nothing occupied and mostly known free."""
        k = self.k
        grid = self.frame.grid
        blocks = self.fine_states().reshape(grid.rows, k, grid.cols, k)
        occ = np.any(blocks == OCCUPIED, axis=(1, 3))
        free_frac = np.mean(blocks == FREE, axis=(1, 3))
        return ~occ & (free_frac >= min_free_fraction) & ~self._outside

    def states(self) -> NDArray[np.int8]:
        k = self.k
        grid = self.frame.grid
        fine = self.fine_states()
        blocks = fine.reshape(grid.rows, k, grid.cols, k)
        inside = ~self._fine_outside.reshape(grid.rows, k, grid.cols, k)
        occ = np.any((blocks == OCCUPIED) & inside, axis=(1, 3))
        free = np.all((blocks == FREE) | ~inside, axis=(1, 3))
        out = np.full(grid.shape, UNKNOWN, dtype=np.int8)
        out[free & ~self._outside] = FREE
        out[occ | self._outside] = OCCUPIED
        return out
