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
    inset_m: NDArray[np.float64]  # how far inside the beam's side boundary the centre lies


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


def cone_cells(grid: GridSpec, beam: Beam, half_angle_rad: float, reach_m: float, aperture_m: float = 0.0) -> ConeCells:
    """Cells of ``grid`` whose centres are within ``reach_m`` of the transducer and inside the beam.

    The beam is a cone of half-angle ``half_angle_rad`` that starts ``aperture_m`` wide at the
    transducer (a real transducer is a couple of centimetres across, so the beam near it is not a
    point). ``off_axis_rad`` is the angle from the nearest edge of that aperture.
    """
    res = grid.resolution
    reach = max(reach_m, 0.0)
    half_ap = aperture_m / 2.0
    c, s = math.cos(beam.axis_rad), math.sin(beam.axis_rad)
    # Bounding box of the beam: the aperture ends and the sector's corners and extremes.
    angles = beam.axis_rad + np.array([-half_angle_rad, 0.0, half_angle_rad])
    px, py = -s * half_ap, c * half_ap
    xs = [beam.x + px, beam.x - px, *(beam.x + reach * np.cos(angles) + px), *(beam.x + reach * np.cos(angles) - px)]
    ys = [beam.y + py, beam.y - py, *(beam.y + reach * np.sin(angles) + py), *(beam.y + reach * np.sin(angles) - py)]
    for q in np.arange(-2, 3) * (math.pi / 2):
        if abs(math.remainder(q - beam.axis_rad, 2 * math.pi)) <= half_angle_rad:
            xs.append(beam.x + reach * math.cos(q) + abs(px))
            xs.append(beam.x + reach * math.cos(q) - abs(px))
            ys.append(beam.y + reach * math.sin(q) + abs(py))
            ys.append(beam.y + reach * math.sin(q) - abs(py))
    c0 = max(math.floor((min(xs) - grid.origin_x) / res), 0)
    c1 = min(math.floor((max(xs) - grid.origin_x) / res), grid.cols - 1)
    iy0 = max(math.floor((min(ys) - grid.origin_y) / res), 0)
    iy1 = min(math.floor((max(ys) - grid.origin_y) / res), grid.rows - 1)
    if c1 < c0 or iy1 < iy0:
        empty_i = np.zeros(0, dtype=np.int64)
        empty_f = np.zeros(0)
        return ConeCells(empty_i, empty_i, empty_f, empty_f, empty_f)
    dx = (grid.origin_x + (np.arange(c0, c1 + 1) + 0.5) * res - beam.x)[None, :]
    dy = (grid.origin_y + (np.arange(iy0, iy1 + 1) + 0.5) * res - beam.y)[:, None]
    along = dx * c + dy * s
    lateral = dy * c - dx * s
    spread = np.maximum(np.abs(lateral) - half_ap, 0.0)
    dist = np.hypot(dx, dy)
    inset = along * math.tan(half_angle_rad) - spread
    inside = (along > 0) & (dist <= reach) & (inset >= 0)
    iy, ix = np.nonzero(inside)
    off = np.arctan2(spread[iy, ix], along[iy, ix]) * np.sign(lateral[iy, ix])
    return ConeCells(
        rows=(grid.rows - 1 - (iy + iy0)).astype(np.int64),
        cols=(ix + c0).astype(np.int64),
        dist_m=dist[iy, ix],
        off_axis_rad=off,
        inset_m=inset[iy, ix],
    )
