"""Position fixes from the room's surveyed box: a side sonar that meets a box edge head-on measures
the robot's distance to that wall, which bounds dead-reckoning drift along that axis.

Only used when the map size is known (the paper's setting). A reading counts when the beam points
within a few degrees of an axis, the echo is short and strong, and the wall it implies lies within a
few centimetres of the box edge; anything else (furniture against the wall, a glancing echo) is
ignored.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.mapping.base import MapFrame
from robot.mapping.geometry import place_beams
from robot.world import Pose


class BoxFixConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    axis_tolerance_deg: float = Field(default=2.0, gt=0.0, le=20.0)  # beam within this of an axis
    max_range_m: float = Field(default=1.2, gt=0.0)  # only short echoes
    # Tight gate, small gain: in a room that is not a rectangle an angled wall can pass close to the
    # box edge, and a loose gate let such echoes drag the estimate (hexagon: 27 cm of error at 12 cm).
    gate_m: float = Field(default=0.05, gt=0.0)  # the implied wall must be this close to the box edge
    gain: float = Field(default=0.3, gt=0.0, le=1.0)  # share of the offset corrected per sweep


def box_fix(
    frame: MapFrame, robot: RobotConfig, pose: Pose, ranges_m: NDArray[np.float64], config: BoxFixConfig
) -> tuple[float, float]:
    """(dx, dy) [m] to add to the estimated position, from echoes off the room box's walls."""
    if frame.extent is None or not config.enabled:
        return 0.0, 0.0
    min_x, min_y, max_x, max_y = frame.extent
    tol = math.radians(config.axis_tolerance_deg)
    dxs: list[float] = []
    dys: list[float] = []
    for beam in place_beams(pose, ranges_m, robot):
        if not beam.echo or beam.range_m > config.max_range_m:
            continue
        axis = math.remainder(beam.axis_rad, 2 * math.pi)
        for target, horizontal, edge in (
            (0.0, True, max_x),
            (math.pi, True, min_x),
            (math.pi / 2, False, max_y),
            (-math.pi / 2, False, min_y),
        ):
            if abs(math.remainder(axis - target, 2 * math.pi)) > tol:
                continue
            if horizontal:
                wall = beam.x + beam.range_m * math.cos(axis)
                offset = edge - wall
                if abs(offset) <= config.gate_m:
                    dxs.append(offset)
            else:
                wall = beam.y + beam.range_m * math.sin(axis)
                offset = edge - wall
                if abs(offset) <= config.gate_m:
                    dys.append(offset)
    dx = config.gain * float(np.median(dxs)) if dxs else 0.0
    dy = config.gain * float(np.median(dys)) if dys else 0.0
    return dx, dy
