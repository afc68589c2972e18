"""Beam geometry on a grid: which cells a sonar cone covers, at what range and off-axis angle."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig
from robot.grid import GridSpec
from robot.world import Pose


class Beam(NamedTuple):
    """One sonar reading placed in the map frame (a named tuple: every sweep places its beams twice,
    for the box fixes and the mapper, and a tuple is several times cheaper to make than a dataclass)."""

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
    for mount, r in zip(robot.sonars, np.asarray(ranges_m, dtype=np.float64).tolist(), strict=True):
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


@dataclass(frozen=True)
class Cones:
    """The cells of several beams' cones at once, beam after beam; ``starts[i]:starts[i + 1]`` are beam i's."""

    cells: ConeCells
    starts: NDArray[np.int64]  # one more than there are beams


def _bounds(
    grid: GridSpec, beam: Beam, half_angle_rad: float, reach: float, half_ap: float, c: float, s: float
) -> tuple[int, int, int, int]:
    """Column and bottom-up row span of the cells that can hold ``beam``'s cone (empty if c1 < c0).

    ``c`` and ``s`` are the cosine and sine of the beam's axis. The cone lies within half the
    aperture of the transducer, its three edge points and the sector's extremes along x and y."""
    axis = beam.axis_rad
    xs = [beam.x, beam.x + reach * math.cos(axis - half_angle_rad), beam.x + reach * c]
    ys = [beam.y, beam.y + reach * math.sin(axis - half_angle_rad), beam.y + reach * s]
    xs.append(beam.x + reach * math.cos(axis + half_angle_rad))
    ys.append(beam.y + reach * math.sin(axis + half_angle_rad))
    for k in range(-2, 3):  # the sector's extremes along x and y, where they lie inside it
        q = k * (math.pi / 2)
        if abs(math.remainder(q - axis, 2 * math.pi)) <= half_angle_rad:
            xs.append(beam.x + reach * math.cos(q))
            ys.append(beam.y + reach * math.sin(q))
    # Half the aperture either side of every point; rounding is monotonic, so the extreme point
    # moved by it is the extreme of the moved points.
    ax, ay = abs(s * half_ap), abs(c * half_ap)
    res = grid.resolution
    c0 = max(math.floor((min(xs) - ax - grid.origin_x) / res), 0)
    c1 = min(math.floor((max(xs) + ax - grid.origin_x) / res), grid.cols - 1)
    iy0 = max(math.floor((min(ys) - ay - grid.origin_y) / res), 0)
    iy1 = min(math.floor((max(ys) + ay - grid.origin_y) / res), grid.rows - 1)
    return c0, c1, iy0, iy1


def cones(
    grid: GridSpec, beams: list[Beam], half_angle_rad: float, reaches_m: list[float], aperture_m: float = 0.0
) -> Cones:
    """Cells of ``grid`` whose centres are within each beam's reach of its transducer and inside its beam.

    A beam is a cone of half-angle ``half_angle_rad`` that starts ``aperture_m`` wide at the
    transducer (a real transducer is a couple of centimetres across, so the beam near it is not a
    point). ``off_axis_rad`` is the angle from the nearest edge of that aperture. All beams are
    computed in one pass over their bounding boxes, laid end to end.
    """
    res = grid.resolution
    half_ap = aperture_m / 2.0
    n = len(beams)
    span_rows: list[tuple[int, int, int, int]] = []  # c0, width, iy0, height
    param_rows: list[tuple[float, float, float, float, float]] = []  # x, y, cos, sin, reach
    for beam, reach in zip(beams, reaches_m, strict=True):
        reach = max(reach, 0.0)
        cos_a, sin_a = math.cos(beam.axis_rad), math.sin(beam.axis_rad)
        span = (0, 0, 0, 0)
        if reach > 0.0:
            c0, c1, iy0, iy1 = _bounds(grid, beam, half_angle_rad, reach, half_ap, cos_a, sin_a)
            if c1 >= c0 and iy1 >= iy0:
                span = (c0, c1 - c0 + 1, iy0, iy1 - iy0 + 1)
        span_rows.append(span)
        param_rows.append((beam.x, beam.y, cos_a, sin_a, reach))
    spans = np.array(span_rows, dtype=np.int64).reshape(n, 4)
    params = np.array(param_rows, dtype=np.float64).reshape(n, 5)
    sizes = spans[:, 1] * spans[:, 3]
    box_starts = np.array([0, *itertools.accumulate(sizes.tolist())], dtype=np.int64)
    local = np.arange(int(box_starts[-1]), dtype=np.float64) - np.repeat(box_starts[:-1].astype(np.float64), sizes)
    width = np.repeat(spans[:, 1].astype(np.float64), sizes)
    row = np.floor((local + 0.5) / width)  # exact: small whole numbers
    col = local - row * width
    # Cell centres relative to each transducer.
    dx = np.repeat(grid.origin_x + (spans[:, 0] + 0.5) * res - params[:, 0], sizes) + col * res
    dy = np.repeat(grid.origin_y + (spans[:, 2] + 0.5) * res - params[:, 1], sizes) + row * res
    c = np.repeat(params[:, 2], sizes)
    s = np.repeat(params[:, 3], sizes)
    along = dx * c + dy * s
    lateral = dy * c - dx * s
    spread = np.maximum(np.abs(lateral) - half_ap, 0.0)
    inset = along * math.tan(half_angle_rad) - spread
    reach_b = np.repeat(params[:, 4], sizes)
    inside = np.flatnonzero((along > 0) & (dx * dx + dy * dy <= reach_b * reach_b) & (inset >= 0))
    dist = np.hypot(dx[inside], dy[inside])
    keep = dist <= reach_b[inside]  # the squared test above can round the other way at the very edge
    inside, dist = inside[keep], dist[keep]
    off = np.arctan2(spread[inside], along[inside]) * np.sign(lateral[inside])
    # Each cell's place in its box, back to grid indices (each box holds its beam's cells).
    starts = np.searchsorted(inside, box_starts)
    inside_sizes = starts[1:] - starts[:-1]
    ix = np.repeat(spans[:, 0], inside_sizes) + col[inside].astype(np.int64)
    iy = np.repeat(spans[:, 2], inside_sizes) + row[inside].astype(np.int64)
    cells = ConeCells(
        rows=grid.rows - 1 - iy,
        cols=ix,
        dist_m=dist,
        off_axis_rad=off,
        inset_m=inset[inside],
    )
    return Cones(cells, starts)


def cone_cells(grid: GridSpec, beam: Beam, half_angle_rad: float, reach_m: float, aperture_m: float = 0.0) -> ConeCells:
    """One beam's cone: see :func:`cones`."""
    return cones(grid, [beam], half_angle_rad, [reach_m], aperture_m).cells
