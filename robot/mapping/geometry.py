"""Beam geometry on a grid: which cells a sonar cone covers, at what range and off-axis angle."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig
from robot.grid import GridSpec
from robot.world import Pose


@dataclass(frozen=True)
class Beam:
    """One sonar reading placed in the map frame."""

    x: float  # transducer position [m]
    y: float
    axis_rad: float  # beam axis, map frame
    range_m: float
    echo: bool  # False: no echo within max range


@dataclass(frozen=True)
class ConeCells:
    """Cells whose centres lie in a cone, flattened: index arrays plus polar coordinates."""

    rows: NDArray[np.int64]
    cols: NDArray[np.int64]
    dist_m: NDArray[np.float64]  # centre distance from the transducer
    off_axis_rad: NDArray[np.float64]  # signed angle from the beam axis


def place_beams(pose: Pose, ranges_m: NDArray[np.float64], robot: RobotConfig) -> list[Beam]:
    """Turn a sweep taken at ``pose`` into beams in the map frame."""
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    max_r = robot.sonar.max_range_m
    beams = []
    for mount, r in zip(robot.sonars, ranges_m, strict=True):
        r = float(r)
        if not math.isfinite(r):
            r = max_r
        beams.append(
            Beam(
                x=pose.x + c * mount.offset_x_m - s * mount.offset_y_m,
                y=pose.y + s * mount.offset_x_m + c * mount.offset_y_m,
                axis_rad=pose.theta + math.radians(mount.bearing_deg),
                range_m=min(r, max_r),
                echo=r < max_r - 1e-6,
            )
        )
    return beams


def cone_cells(grid: GridSpec, beam: Beam, half_angle_rad: float, reach_m: float) -> ConeCells:
    """Cells of ``grid`` whose centres are within ``reach_m`` of the transducer and inside the cone."""
    res = grid.resolution
    reach = max(reach_m, 0.0)
    # Bounding box of the sector, clipped to the grid.
    angles = beam.axis_rad + np.array([-half_angle_rad, 0.0, half_angle_rad])
    xs = np.concatenate([[beam.x], beam.x + reach * np.cos(angles)])
    ys = np.concatenate([[beam.y], beam.y + reach * np.sin(angles)])
    # The sector's arc may bulge past its chord in the direction of the axis quadrants.
    for q in np.arange(-2, 3) * (math.pi / 2):
        a = q + round((beam.axis_rad - q) / (2 * math.pi)) * 2 * math.pi
        if abs(math.remainder(a - beam.axis_rad, 2 * math.pi)) <= half_angle_rad:
            xs = np.append(xs, beam.x + reach * math.cos(a))
            ys = np.append(ys, beam.y + reach * math.sin(a))
    c0 = max(int(math.floor((xs.min() - grid.origin_x) / res)), 0)
    c1 = min(int(math.floor((xs.max() - grid.origin_x) / res)), grid.cols - 1)
    iy0 = max(int(math.floor((ys.min() - grid.origin_y) / res)), 0)
    iy1 = min(int(math.floor((ys.max() - grid.origin_y) / res)), grid.rows - 1)
    if c1 < c0 or iy1 < iy0:
        empty_i = np.zeros(0, dtype=np.int64)
        empty_f = np.zeros(0)
        return ConeCells(empty_i, empty_i, empty_f, empty_f)
    cx = grid.origin_x + (np.arange(c0, c1 + 1) + 0.5) * res - beam.x
    cy = grid.origin_y + (np.arange(iy0, iy1 + 1) + 0.5) * res - beam.y
    dx = cx[None, :]
    dy = cy[:, None]
    dist = np.hypot(dx, dy)
    off = np.angle(np.exp(1j * (np.arctan2(dy, dx) - beam.axis_rad)))
    inside = (dist <= reach) & (np.abs(off) <= half_angle_rad)
    iy, ix = np.nonzero(inside)
    return ConeCells(
        rows=(grid.rows - 1 - (iy + iy0)).astype(np.int64),
        cols=(ix + c0).astype(np.int64),
        dist_m=dist[iy, ix],
        off_axis_rad=off[iy, ix],
    )
