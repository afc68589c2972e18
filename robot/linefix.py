"""Position fixes from straight walls the robot has mapped itself, at any angle.

The box fixes (``robot.boxfix``) need a wall on an edge of the surveyed room box. A room turned to
the grid, a round room or a polygon has few such walls or none, and its estimate drifts. But a
straight wall once found is a landmark: a beam meets it at its nearest point when the wall's normal
lies inside the beam's cone, so its range then is the transducer's distance to the wall, whatever
the wall's angle, and the difference from the distance the estimate implies is the position error
across the wall.

Walls are found from the last sweeps' echoes (``robot.mapping.tangents``, the Hough vote the final
map uses) and frozen when found: later echoes, taken while the estimate drifted, do not move them.
A landmark keeps the error the estimate had when it was found. In a room of unknown size (real
hardware, no surveyed box) there are no box fixes, and every wall found is a landmark. Where the
room box is known the box fixes come first, and these fixes are off unless ``with_known_box``
asks for them: then walls along the grid's axes are left to the box fixes, and new walls are
looked for only while an axis has had no box fix for a while.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.mapping.geometry import place_beams
from robot.mapping.tangents import Line, TangentLines, TangentParams
from robot.world import Pose


class LineFixConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    # Also where the room box is known. There the box fixes hold the estimate: over 64 fresh rooms
    # (mixed --seed 5511 and 6611) these fixes took the mean final position error from 2.5 and 2.8
    # to 2.3 and 2.6 cm, but F1 did not follow (6 runs up, 10 down; the means 0.9864 -> 0.9864 and
    # 0.9833 -> 0.9826), so they are off by default. In a room of unknown size they are the only
    # fixes there are.
    with_known_box: bool = False
    window_sweeps: int = Field(default=60, ge=2)  # walls are looked for in this many last sweeps' echoes ...
    refresh_sweeps: int = Field(default=20, ge=1)  # ... every this many sweeps, while an axis of the
    # room box has had no box fix for idle_sweeps sweeps (a search takes a few milliseconds)
    idle_sweeps: int = Field(default=20, ge=0)
    min_echoes: int = Field(default=30, ge=3)  # a landmark: this many echoes agree on it ...
    max_scatter_m: float = Field(default=0.01, gt=0.0)  # ... within this rms ...
    min_length_m: float = Field(default=0.5, gt=0.0)  # ... over this stretch
    # ... and, when the room box is known, turned this far off the grid's axes (as far as a wall
    # found must be to cut the cells it crosses): along an axis the box fixes serve, and a face
    # found a degree turned off its true axis fixed room3's estimate wrong by centimetres along it
    # (F1 0.987 -> 0.978 over 5 seeds). In a room of unknown size every wall is a landmark.
    min_axis_angle_deg: float = Field(default=3.0, ge=0.0, le=45.0)
    max_landmarks: int = Field(default=64, ge=1)
    max_range_m: float = Field(default=1.2, gt=0.0)  # only short echoes fix
    cone_margin_deg: float = Field(default=4.0, ge=0.0)  # the wall's normal this far inside the cone
    end_margin_m: float = Field(default=0.1, ge=0.0)  # the nearest point this far inside the stretch
    gate_m: float = Field(default=0.05, gt=0.0)  # a reading this close to the landmark counts
    gain: float = Field(default=0.3, gt=0.0, le=1.0)  # share of the error corrected per sweep


class LineFixes:
    """Landmark walls from the recent echoes, and the position error they show in a sweep."""

    def __init__(self, robot: RobotConfig, config: LineFixConfig, box_known: bool = True) -> None:
        self.robot = robot
        self.config = config
        self.min_axis_rad = math.radians(config.min_axis_angle_deg) if box_known else 0.0
        self.half = math.radians(robot.sonar.beam_width_deg) / 2.0
        self.params = TangentParams()
        self.landmarks: list[Line] = []
        self.fixes = 0  # sweeps whose position the landmarks corrected
        self._recent: list[tuple[list[float], list[float], list[float], list[float]]] = []
        self._sweeps = 0

    def observe(self, pose: Pose, ranges_m: NDArray[np.float64], box_idle: int) -> None:
        """A sweep's echoes at its (corrected) pose; every ``refresh_sweeps`` sweeps, when an axis
        has had no box fix for ``box_idle`` sweeps, new walls found in the window become landmarks."""
        c = self.config
        beams = [b for b in place_beams(pose, ranges_m, self.robot) if b.echo]
        self._recent.append(
            ([b.x for b in beams], [b.y for b in beams], [b.axis_rad for b in beams], [b.range_m for b in beams])
        )
        del self._recent[: -c.window_sweeps]
        self._sweeps += 1
        searching = box_idle >= c.idle_sweeps and len(self.landmarks) < c.max_landmarks
        if searching and self._sweeps % c.refresh_sweeps == 0:
            self._refresh()

    def _refresh(self) -> None:
        c = self.config
        tangents = TangentLines(self.half, self.params)
        for xs, ys, axes, ranges in self._recent:
            tangents.add(xs, ys, axes, ranges)
        turn, apart = math.radians(self.params.same_deg), self.params.same_m
        for line in tangents.lines():
            if line.echoes < c.min_echoes or line.scatter > c.max_scatter_m or line.s1 - line.s0 < c.min_length_m:
                continue
            if line.off_axis_rad < self.min_axis_rad:
                continue
            if any(line.near(old, turn, apart) or old.near(line, turn, apart) for old in self.landmarks):
                continue
            self.landmarks.append(line)
            if len(self.landmarks) >= c.max_landmarks:
                return

    def offset(self, pose: Pose, ranges_m: NDArray[np.float64]) -> tuple[float, float] | None:
        """The correction of the position (true minus estimated, times the gain) [m] that the
        landmarks show in this sweep, or None when no reading meets one."""
        if not self.landmarks:
            return None
        c = self.config
        within = self.half - math.radians(c.cone_margin_deg)
        normals: list[tuple[float, float]] = []
        errors: list[float] = []
        for beam in place_beams(pose, ranges_m, self.robot):
            if not beam.echo or beam.range_m > c.max_range_m:
                continue
            best: tuple[float, float, float, float] | None = None  # |error|, nx, ny, error
            for line in self.landmarks:
                if abs(math.remainder(beam.axis_rad - line.theta, 2 * math.pi)) > within:
                    continue
                expected = -line.depth_at(beam.x, beam.y)  # the transducer's distance to the wall
                if expected <= 0.0:
                    continue
                # The foot of the perpendicular lies where the transducer does along the wall.
                if not line.s0 + c.end_margin_m <= line.along(beam.x, beam.y) <= line.s1 - c.end_margin_m:
                    continue
                error = expected - beam.range_m
                if abs(error) <= c.gate_m and (best is None or abs(error) < best[0]):
                    best = (abs(error), math.cos(line.theta), math.sin(line.theta), error)
            if best is not None:
                normals.append((best[1], best[2]))
                errors.append(best[3])
        if not errors:
            return None
        n = np.array(normals)
        e = np.array(errors)
        # Least squares over the readings' normals; the small ridge leaves the direction that no
        # normal measured alone.
        shift = np.linalg.solve(n.T @ n + 0.05 * np.eye(2), n.T @ e)
        self.fixes += 1
        return c.gain * float(shift[0]), c.gain * float(shift[1])
