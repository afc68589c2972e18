"""Position fixes from straight walls the robot mapped itself (robot/linefix.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.config import RobotConfig
from robot.linefix import LineFixConfig, LineFixes
from robot.mapping.geometry import place_beams
from robot.world import Pose

ROBOT = RobotConfig()
HALF = math.radians(ROBOT.sonar.beam_width_deg) / 2.0


def _ranges(pose: Pose, normal: float, d: float) -> np.ndarray:
    """A noiseless sweep at ``pose`` in front of an endless straight wall (points p with
    n . p = d, n at ``normal``): each beam hears the wall's nearest point inside its cone."""
    far = ROBOT.sonar.max_range_m
    out = []
    for beam in place_beams(pose, np.full(len(ROBOT.sonars), far), ROBOT):
        dist = d - (math.cos(normal) * beam.x + math.sin(normal) * beam.y)
        off = abs(math.remainder(beam.axis_rad - normal, 2 * math.pi))
        if dist <= 0.0 or off >= math.pi / 2 - HALF:
            out.append(far)
        else:
            out.append(min(dist / math.cos(max(off - HALF, 0.0)), far))
    return np.array(out)


def _drive_along(fixes: LineFixes, normal: float, d: float, distance: float = 0.6) -> None:
    """Sweeps every 5 cm over 2 m along the wall, ``distance`` in front of it, facing it."""
    n = np.array([math.cos(normal), math.sin(normal)])
    t = np.array([-math.sin(normal), math.cos(normal)])
    for s in np.arange(-1.0, 1.001, 0.05):
        x, y = (d - distance) * n + s * t
        pose = Pose(float(x), float(y), normal)
        fixes.observe(pose, _ranges(pose, normal, d), box_idle=100)


def test_a_wall_at_an_angle_becomes_a_landmark_that_measures_the_error_across_it() -> None:
    normal, d = math.radians(20.0), 4.0
    fixes = LineFixes(ROBOT, LineFixConfig())
    _drive_along(fixes, normal, d)
    assert len(fixes.landmarks) == 1
    wall = fixes.landmarks[0]
    assert math.degrees(wall.theta) == pytest.approx(20.0, abs=1.0)
    assert wall.d == pytest.approx(d, abs=0.02)

    n = np.array([math.cos(normal), math.sin(normal)])
    t = np.array([-math.sin(normal), math.cos(normal)])
    true_xy = (d - 0.6) * n + 0.3 * t
    truth = Pose(float(true_xy[0]), float(true_xy[1]), normal)
    ranges = _ranges(truth, normal, d)
    # The estimate 3 cm towards the wall: the correction moves it back along the normal, by the
    # gain's share, and not along the wall.
    believed = Pose(truth.x + 0.03 * n[0], truth.y + 0.03 * n[1], normal)
    shift = fixes.offset(believed, ranges)
    assert shift is not None
    expected = LineFixConfig().gain * -0.03 / 1.05  # the ridge's share of a single normal
    measured = np.array(shift)
    assert float(measured @ n) == pytest.approx(expected, abs=2e-3)
    assert float(measured @ t) == pytest.approx(0.0, abs=1e-3)
    assert fixes.fixes == 1
    # Along the wall the landmark says nothing; past the gate it is not the wall.
    along = Pose(truth.x + 0.05 * t[0], truth.y + 0.05 * t[1], normal)
    assert np.linalg.norm(fixes.offset(along, ranges) or (0.0, 0.0)) < 2e-3
    off = Pose(truth.x + 0.08 * n[0], truth.y + 0.08 * n[1], normal)
    assert fixes.offset(off, ranges) is None


def test_walls_along_the_axes_and_searches_while_the_box_fixes_serve_find_no_landmark() -> None:
    along_axis = LineFixes(ROBOT, LineFixConfig())
    _drive_along(along_axis, math.radians(2.0), 4.0)
    assert along_axis.landmarks == []

    boxed = LineFixes(ROBOT, LineFixConfig())
    normal, d = math.radians(20.0), 4.0
    n = np.array([math.cos(normal), math.sin(normal)])
    t = np.array([-math.sin(normal), math.cos(normal)])
    for s in np.arange(-1.0, 1.001, 0.05):
        x, y = (d - 0.6) * n + s * t
        pose = Pose(float(x), float(y), normal)
        boxed.observe(pose, _ranges(pose, normal, d), box_idle=3)  # a box fix three sweeps ago
    assert boxed.landmarks == []
    assert boxed.offset(Pose(3.0, 1.0, normal), _ranges(Pose(3.0, 1.0, normal), normal, d)) is None


def test_line_fixes_serve_rooms_of_unknown_size_unless_asked_for_with_the_box_or_turned_off() -> None:
    from robot.boxfix import BoxFixConfig
    from robot.grid import GridSpec
    from robot.headingfix import HeadingFixConfig, WallFixes
    from robot.mapping.base import MapFrame

    grid = GridSpec(0.0, 0.0, 0.2, 30, 30)
    boxed = MapFrame(grid=grid, start=Pose(3.0, 1.0, 0.0), extent=(0.0, 0.0, 6.0, 6.0))
    unknown = MapFrame(grid=grid, start=Pose(3.0, 1.0, 0.0), extent=None)

    def lines(frame: MapFrame, config: LineFixConfig) -> LineFixes | None:
        return WallFixes(frame, ROBOT, BoxFixConfig(), HeadingFixConfig(), config).lines

    assert lines(unknown, LineFixConfig()) is not None
    assert lines(unknown, LineFixConfig(enabled=False)) is None
    assert lines(boxed, LineFixConfig()) is None
    with_box = lines(boxed, LineFixConfig(with_known_box=True))
    assert with_box is not None and with_box.min_axis_rad > 0.0


def test_in_a_room_of_unknown_size_a_wall_along_an_axis_is_a_landmark_too() -> None:
    """Without the room box there are no box fixes, so the walls along the axes are the landmarks
    that matter most."""
    fixes = LineFixes(ROBOT, LineFixConfig(), box_known=False)
    _drive_along(fixes, math.radians(2.0), 4.0)
    assert len(fixes.landmarks) == 1
    assert math.degrees(fixes.landmarks[0].theta) == pytest.approx(2.0, abs=1.0)
