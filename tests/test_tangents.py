"""Straight walls from the lines sonar echoes are tangent to (robot.mapping.tangents)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from robot.grid import GridSpec
from robot.mapping.tangents import (
    Line,
    TangentLines,
    TangentParams,
    _off,
    _trimmed_ends,
    box_walls,
    meet_at_corners,
)

HALF = math.radians(15.0)


def _echoes_off_line(theta: float, d: float, places: list[tuple[float, float]], rng: np.random.Generator, std: float):
    """Echoes of the wall n . p = d (n at ``theta``) from ``places``, by beams whose cones hold the
    wall's normal (axes off it by up to 12 degrees): the range is the distance to the wall."""
    xs, ys, axes, ranges = [], [], [], []
    for x, y in places:
        for off in (-12.0, -4.0, 7.0):
            xs.append(x)
            ys.append(y)
            axes.append(theta + math.radians(off))
            ranges.append(d - (math.cos(theta) * x + math.sin(theta) * y) + rng.normal(0.0, std))
    return xs, ys, axes, ranges


def test_a_wall_at_an_angle_is_found_where_it_runs() -> None:
    rng = np.random.default_rng(0)
    theta, d = math.radians(20.0), 2.0  # a wall facing a robot that drives along it
    t = (-math.sin(theta), math.cos(theta))
    places = []
    for s in np.arange(-0.6, 0.61, 0.2):
        foot = (d * math.cos(theta) + s * t[0], d * math.sin(theta) + s * t[1])
        for dist in (0.5, 0.8):
            places.append((foot[0] - dist * math.cos(theta), foot[1] - dist * math.sin(theta)))
    lines = TangentLines(HALF, TangentParams(enabled=True))
    lines.add(*_echoes_off_line(theta, d, places, rng, 0.01))
    found = lines.lines()
    assert len(found) == 1
    wall = found[0]
    assert abs(math.degrees(math.remainder(wall.theta - theta, 2 * math.pi))) <= 1.0
    assert abs(wall.d - d) <= 0.01
    assert wall.s0 <= -0.45 and wall.s1 >= 0.45  # the stretch the echoes touched


def test_echoes_of_one_point_from_places_in_a_row_make_no_wall() -> None:
    """Driving straight at a chair leg: every echo is tangent to the line across the approach at
    the leg, but they all touch it at one point."""
    leg = np.array([2.0, 1.0])
    xs, ys, axes, ranges = [], [], [], []
    for dist in np.arange(0.3, 1.5, 0.05):
        for off in (-10.0, 0.0, 10.0):
            xs.append(float(leg[0] - dist))
            ys.append(float(leg[1]))
            axes.append(math.radians(off))
            ranges.append(float(dist))
    lines = TangentLines(HALF, TangentParams(enabled=True))
    lines.add(xs, ys, axes, ranges)
    assert lines.lines() == []


def test_long_echoes_do_not_vote() -> None:
    lines = TangentLines(HALF, TangentParams(enabled=True, max_range_m=1.0))
    lines.add([0.0] * 20, [0.0] * 20, [0.0] * 20, [1.5] * 20)
    assert lines.lines() == []


def test_a_cell_is_cut_when_the_wall_reaches_past_the_margin_into_it() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 3, 3)
    lines = TangentLines(HALF, TangentParams(enabled=True, margin_m=0.015, min_axis_angle_deg=0.0))
    # A vertical wall at x = 0.39, facing -x... i.e. n = (+1, 0) points into the wall: the wall
    # fills x > 0.39. It crosses the middle column's cells (0.2-0.4) 1 cm from their edge: less
    # than the margin, so they stay; at x = 0.37 it reaches 3 cm into them.
    near_edge = Line(theta=0.0, d=0.39, s0=0.0, s1=0.6, echoes=10, scatter=0.01)
    assert not lines.cut_cells(grid, [near_edge]).any()
    inside = Line(theta=0.0, d=0.37, s0=0.0, s1=0.6, echoes=10, scatter=0.01)
    cut = lines.cut_cells(grid, [inside])
    assert cut[:, 1].all() and not cut[:, 0].any() and not cut[:, 2].any()
    # Only along the stretch the echoes touched, give or take half a cell: not the row at y = 0.5.
    short = Line(theta=0.0, d=0.37, s0=0.0, s1=0.25, echoes=10, scatter=0.01)
    _, ys = grid.centers()
    assert lines.cut_cells(grid, [short])[:, 1].tolist() == (ys[:, 1] < 0.4).tolist()
    # By default a face along an axis is left to the evidence grid; turned by 5 degrees it is not.
    default = TangentLines(HALF, TangentParams(enabled=True))
    assert not default.cut_cells(grid, [inside]).any()
    turned = Line(theta=math.radians(5.0), d=0.37, s0=0.0, s1=0.6, echoes=10, scatter=0.01)
    assert default.cut_cells(grid, [turned])[:, 1].any()


def test_a_wall_a_little_off_an_axis_cuts_only_the_cells_it_reaches_well_into() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 6, 3)
    lines = TangentLines(HALF, TangentParams(enabled=True))
    p = lines.params
    assert p.near_axis_min_deg <= 2.0 < p.min_axis_angle_deg and p.near_axis_margin_m == pytest.approx(0.03)
    # A wall turned 2 degrees off the y axis, through (0.399, 0): it reaches sin(2 deg) * y_top + 1 mm
    # past the middle column's top right corners, 3 cm or more only in the top two rows (y_top 1.0, 1.2).
    theta = math.radians(2.0)
    leaning = Line(theta=theta, d=0.399 * math.cos(theta), s0=-0.1, s1=1.3, echoes=10, scatter=0.01)
    cut = lines.cut_cells(grid, [leaning])
    assert cut[:, 1].tolist() == [True, True, False, False, False, False]  # row 0 holds the largest y
    assert not cut[:, 0].any() and not cut[:, 2].any()
    # At a degree off the axis it is left to the evidence grid, as a face along the axis.
    theta = math.radians(1.0)
    nearly = Line(theta=theta, d=0.399 * math.cos(theta), s0=-0.1, s1=1.3, echoes=10, scatter=0.01)
    assert not lines.cut_cells(grid, [nearly]).any()


def test_a_wall_leaning_off_a_box_edge_cuts_every_cell_it_crosses() -> None:
    """Along a box edge, a wall that leans off it leaves the edge at a vertex: every cell along it
    holds a sliver of wall, so its cut takes no margin (``box_lean_margin_m``)."""
    grid = GridSpec(0.0, 0.0, 0.2, 6, 3)
    lines = TangentLines(HALF, TangentParams(enabled=True))
    theta = math.radians(2.0)
    leaning = Line(theta=theta, d=0.399 * math.cos(theta), s0=-0.1, s1=1.3, echoes=10, scatter=0.01)
    assert lines.leans(leaning)
    assert lines.cut_cells(grid, [leaning])[:, 1].tolist() == [True, True, False, False, False, False]
    cut = lines.cut_cells(grid, [leaning], lines.params.box_lean_margin_m)
    assert cut[:, 1].all() and not cut[:, 0].any() and not cut[:, 2].any()
    # A degree off an axis is within what the box's own walls are found at.
    theta = math.radians(1.0)
    assert not lines.leans(Line(theta=theta, d=0.4 * math.cos(theta), s0=-0.1, s1=1.3, echoes=10, scatter=0.01))


def test_a_polygon_wall_leaning_off_the_box_edge_blocks_the_cells_it_clips() -> None:
    """A room whose left and right walls lean 2 degrees off its box edges, from vertices on them: every
    cell of the grid's first and last columns along them holds a sliver of wall. Those walls were
    taken for the box's own and the cells near the vertices, clipped by a centimetre or two, stayed
    white."""
    from robot.runner import simulate
    from robot.settings import load_run_config
    from robot.world import world_from_dict

    room = {
        "name": "leaning-sides",
        "boundary": [
            [3.89, 1.72], [3.95, 3.33], [2.75, 4.48], [1.08, 3.98], [0.0, 3.37],
            [0.06, 1.81], [0.74, 0.57], [2.64, 0.0], [3.13, 0.97],
        ],
        "start": {"x": 2.93, "y": 2.1, "theta_deg": 0.0},
    }  # fmt: skip
    world = world_from_dict(room, "leaning-sides.toml")
    cfg = load_run_config()
    tangents = cfg.slam.logodds.tangents
    before = tangents.model_copy(update={"box_lean_min_deg": 45.0})  # a wall along an edge was the box's
    off = cfg.slam.model_copy(update={"logodds": cfg.slam.logodds.model_copy(update={"tangents": before})})
    kept = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    lost = simulate(world, cfg.robot, cfg.noise, off, seed=0)
    assert kept.trajectory == lost.trajectory  # only the final map changes
    assert kept.metrics.recall > lost.metrics.recall
    assert kept.metrics.f1 > lost.metrics.f1


def test_walls_are_extended_to_the_corner_where_they_meet() -> None:
    """Echoes seldom touch a wall near a corner, so the stretches found stop short of it."""
    east = Line(theta=0.0, d=1.0, s0=0.2, s1=0.7, echoes=20, scatter=0.01)  # x = 1, touched for y 0.2-0.7
    north = Line(theta=math.pi / 2, d=1.0, s0=-0.75, s1=-0.2, echoes=20, scatter=0.01)  # y = 1, x 0.2-0.75
    params = TangentParams(corner_reach_m=0.4)
    a, b = meet_at_corners([east, north], params)
    assert (a.s0, a.s1) == pytest.approx((0.2, 1.0)) and (b.s0, b.s1) == pytest.approx((-1.0, -0.2))
    assert a.along(1.0, 1.0) == pytest.approx(1.0) and b.along(1.0, 1.0) == pytest.approx(-1.0)
    # A corner farther than the reach from either stretch is not assumed.
    assert meet_at_corners([east, north], TangentParams(corner_reach_m=0.2)) == [east, north]
    # Nor between walls a few degrees apart, which meet far away if at all.
    turned = Line(theta=math.radians(10.0), d=1.05, s0=1.0, s1=1.5, echoes=20, scatter=0.01)
    assert meet_at_corners([east, turned], params) == [east, turned]
    # A wall that ends short of another one's stretch (a partition) is extended to it; the other is not.
    partition = Line(theta=0.0, d=0.5, s0=0.2, s1=0.8, echoes=20, scatter=0.01)  # x = 0.5, up to y 0.8
    c, d = meet_at_corners([partition, north], params)
    assert (c.s0, c.s1) == pytest.approx((0.2, 1.0)) and d == north
    # Walls that cross within both stretches are left as they are.
    crossing = Line(theta=0.0, d=0.5, s0=0.2, s1=1.4, echoes=20, scatter=0.01)
    assert meet_at_corners([crossing, north], params) == [crossing, north]


def test_walls_are_extended_to_the_room_box_they_meet() -> None:
    """A room that is not a box touches its box at vertices: a wall leaving one is extended to the
    box edge, and the box's own edges are not among the walls returned."""
    box = box_walls((0.0, 0.0, 3.0, 2.0))
    assert [(round(math.degrees(w.theta)), w.d) for w in box] == [(0, 3.0), (90, 2.0), (180, -0.0), (-90, -0.0)]
    # x + y = 2.5 (normal at 45 degrees), touched from (1.5, 1.0) to (1.0, 1.5): it meets the top edge
    # at (0.5, 2.0), 0.71 m past the stretch's end, and the other edges farther away.
    theta = math.pi / 4
    slanted = Line(theta=theta, d=2.5 / math.sqrt(2.0), s0=0.0, s1=0.0, echoes=20, scatter=0.01)
    slanted = replace(slanted, s0=slanted.along(1.5, 1.0), s1=slanted.along(1.0, 1.5))
    params = TangentParams(corner_reach_m=0.4)
    assert meet_at_corners([slanted], params) == [slanted]  # no other wall found: as it is
    # The stretch touched up to (0.75, 1.75) ends 0.35 m short of the top edge: it is run on to it.
    near = replace(slanted, s0=slanted.along(1.5, 1.0), s1=slanted.along(0.75, 1.75))
    (out,) = meet_at_corners([near], params, box)
    assert out.s1 == pytest.approx(slanted.along(0.5, 2.0)) and out.s0 == near.s0
    assert meet_at_corners([slanted], params, box) == [slanted]


def test_a_wall_running_towards_the_box_edge_is_extended_to_it() -> None:
    """A wall a few degrees off a box edge meets it metres away, at a vertex echoes seldom reach:
    when its stretch ends near the edge and runs towards it, it is run on to the edge."""
    box = box_walls((-1.0, 0.0, 4.0, 3.0))

    def wall(slope: float, y0: float, x0: float, x1: float) -> Line:
        """y = y0 + slope * x, with the room above it, touched for x in [x0, x1]."""
        theta = math.atan2(-1.0, slope)  # the normal points down, out of the room
        line = Line(theta=theta, d=math.sin(theta) * y0, s0=0.0, s1=0.0, echoes=20, scatter=0.01)
        ends = sorted(line.along(x, y0 + slope * x) for x in (x0, x1))
        return replace(line, s0=ends[0], s1=ends[1])

    # y = 0.2 - 0.1 x (5.7 degrees off the bottom edge, which it meets at x = 2), touched for x 0.3-1.3:
    # the stretch ends 7 cm above the edge and 0.7 m short of it.
    sloping = wall(-0.1, 0.2, 0.3, 1.3)
    params = TangentParams(corner_reach_m=0.4, box_approach_m=0.15)
    (out,) = meet_at_corners([sloping], params, box)
    assert out.s0 == sloping.s0 and out.s1 == pytest.approx(sloping.along(2.0, 0.0))
    # Not without the approach rule: the edge lies past corner_reach_m, at 5.7 degrees.
    assert meet_at_corners([sloping], params.model_copy(update={"box_approach_m": 0.0}), box) == [sloping]
    # Nor when the stretch ends farther from the edge than box_approach_m (12 cm above it, at x = 0.8).
    short = wall(-0.1, 0.2, 0.3, 0.8)
    assert meet_at_corners([short], params.model_copy(update={"box_approach_m": 0.1}), box) == [short]
    # Nor a wall within near_axis_min_deg of the edge (1 degree: left to the evidence grid).
    flat = wall(-math.tan(math.radians(1.0)), 0.05, 0.3, 1.3)
    assert meet_at_corners([flat], params, box) == [flat]


def test_a_wall_parallel_to_a_box_edge_meets_nothing_when_every_angle_approaches_it() -> None:
    """``near_axis_min_deg = 0`` (a setting the config allows) lets any wall approach the box edges:
    a wall parallel to one of them never meets it, and finishing the map divided by zero."""
    box = box_walls((0.0, 0.0, 3.0, 2.0))
    flat = Line(theta=-math.pi / 2, d=-0.3, s0=0.5, s1=1.5, echoes=20, scatter=0.01)  # y = 0.3, facing down
    params = TangentParams(near_axis_min_deg=0.0, box_approach_m=0.15)
    assert meet_at_corners([flat], params, box) == [flat]
    # It still runs on to the side edge that its stretch ends near (x = 0.1, 10 cm from x = 0).
    (out,) = meet_at_corners([replace(flat, s0=0.1)], params, box)
    assert out.s0 == pytest.approx(0.0) and out.s1 == flat.s1


def test_a_line_must_run_along_occupied_evidence() -> None:
    fine = GridSpec(0.0, 0.0, 0.05, 40, 40)
    occupied = np.zeros(fine.shape, dtype=bool)
    occupied[:, 20] = True  # a wall at x = 1.0-1.05
    lines = TangentLines(HALF, TangentParams(enabled=True))
    along_wall = Line(theta=0.0, d=1.0, s0=0.2, s1=1.8, echoes=10, scatter=0.01)
    across_floor = Line(theta=0.0, d=0.5, s0=0.2, s1=1.8, echoes=10, scatter=0.01)
    assert lines.on_evidence(along_wall, fine, occupied)
    assert not lines.on_evidence(across_floor, fine, occupied)


def test_straight_walls_recover_cells_that_angled_walls_clip() -> None:
    """A room whose walls all run at angles: without the walls found from tangents, cells that a
    wall clips at a corner stay white (the truth calls them blocked); with them the map finds them."""
    from robot.runner import simulate
    from robot.settings import load_run_config
    from robot.world import load_world

    cfg = load_run_config()
    world = load_world("pentagon")
    off = cfg.slam.model_copy(
        update={"logodds": cfg.slam.logodds.model_copy(update={"tangents": TangentParams(enabled=False)})}
    )
    with_walls = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    without = simulate(world, cfg.robot, cfg.noise, off, seed=0)
    # The walls only change the final map, never the run itself.
    assert with_walls.trajectory == without.trajectory
    assert with_walls.metrics.recall > without.metrics.recall
    assert with_walls.metrics.f1 > without.metrics.f1


def test_face_cells_past_a_wall_leaning_off_the_box_edge_are_left_to_their_evidence() -> None:
    """The few centimetres inside the room box count as its wall's face (free floor up to it), but
    not behind a wall found a little off the edge's direction: in a room that is not a box, such a
    wall meets the box edge at a vertex and runs just inside it."""
    from robot.config import RobotConfig
    from robot.mapping.base import MapFrame
    from robot.mapping.logodds import LogOddsMapper
    from robot.world import Pose

    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    mapper = LogOddsMapper(MapFrame(grid=grid, start=Pose(1.5, 1.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0)), RobotConfig())

    def leaning(x_top: float) -> Line:
        """The left wall, from (0, 0.3) to (x_top, 2.7), touched all along."""
        theta = math.atan2(x_top, -2.4)  # the normal into the wall
        d = math.sin(theta) * 0.3
        s0, s1 = sorted(-math.sin(theta) * x + math.cos(theta) * y for x, y in ((0.0, 0.3), (x_top, 2.7)))
        return Line(theta=theta, d=d, s0=s0, s1=s1, echoes=40, scatter=0.01)

    def face_past(line: Line, x: float, y: float) -> bool:
        row, col = mapper.fine.world_to_index(x, y)
        past = np.zeros(mapper.fine.shape, dtype=bool)
        past[mapper._inner] = mapper._past_slanting_walls([line]) & mapper._face_band
        return bool(past[row, col])

    wall = leaning(0.1)  # 2.4 degrees off the edge
    assert math.degrees(abs(math.remainder(wall.theta, math.pi / 2))) == pytest.approx(2.39, abs=0.01)
    # Where the wall runs 3 cm or more inside the edge, the face cell (0-5 cm) lies behind it.
    assert face_past(wall, 0.025, 1.025) and face_past(wall, 0.025, 2.525)
    # Near the vertex the wall is on the edge; past the stretch the echoes touched, nothing is known;
    # the other edges keep their faces.
    assert not face_past(wall, 0.025, 0.375)
    assert not face_past(wall, 0.025, 2.925)
    assert not face_past(wall, 2.975, 1.525) and not face_past(wall, 1.525, 0.025)
    # A wall found 0.8 degrees off the edge is the box's own (seen with some pose error) ...
    assert not face_past(leaning(0.035), 0.025, 2.525)
    # ... but one 1.2 degrees off leans: 4.6 cm inside the edge at the top of its stretch.
    assert face_past(leaning(0.05), 0.025, 2.525)


def test_the_box_face_is_held_free_only_along_edges_where_echoes_found_a_wall() -> None:
    """A room that is not a box meets its box at vertices; along those edges the face cells hold its
    walls. The final map holds the face free along an edge where a wall was found on it, or near
    where echoes touched it and no echoes beside fell short of it; elsewhere the face cells keep
    their own evidence."""
    from robot.config import RobotConfig
    from robot.mapping.base import MapFrame
    from robot.mapping.logodds import LogOddsMapper
    from robot.world import Pose

    extent = (0.0, 0.0, 3.0, 3.0)
    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    mapper = LogOddsMapper(MapFrame(grid=grid, start=Pose(1.5, 1.5, 0.0), extent=extent), RobotConfig())
    assert mapper.params.face_needs_wall and mapper.params.face_min_touches == 2
    tangents = mapper._tangents
    assert tangents is not None

    def kept(walls: list[Line], x: float, y: float) -> bool:
        row, col = mapper.fine.world_to_index(x, y)
        out = np.zeros(mapper.fine.shape, dtype=bool)
        out[mapper._inner] = mapper._faces_of_found_edges(tangents, extent, walls) & mapper._face_band
        return bool(out[row, col])

    # Nothing found and no echo: no face is held free.
    assert not kept([], 0.025, 1.525) and not kept([], 1.525, 0.025)
    # The left wall found (0.8 degrees and 1 cm off the edge): its whole face is held, no other.
    left = Line(theta=math.pi + math.radians(0.8), d=0.01, s0=-2.0, s1=-1.0, echoes=40, scatter=0.01)
    assert kept([left], 0.025, 0.125) and kept([left], 0.025, 2.875)
    assert not kept([left], 1.525, 0.025) and not kept([left], 2.975, 1.525)
    # Found 1.2 degrees off, it is a wall leaning off the edge, not the box's own.
    leaning = Line(theta=math.pi + math.radians(1.2), d=0.01, s0=-2.0, s1=-1.0, echoes=40, scatter=0.01)
    assert not kept([leaning], 0.025, 1.525)
    # Two echoes that touched the bottom edge at x = 1.5 (from 0.5 m above it, looking down) hold
    # its face within 20 cm of there (two sweeps a step apart); one echo does not.
    tangents.add([1.5], [0.5], [-math.pi / 2], [0.5])
    assert not kept([], 1.525, 0.025)
    tangents.add([1.52], [0.5], [-math.pi / 2], [0.5])
    assert kept([], 1.525, 0.025) and kept([], 1.575, 0.025) and kept([], 1.675, 0.025)
    assert not kept([], 1.725, 0.025) and not kept([], 0.025, 1.525)
    # Echoes from beside those places that fell 5 cm short: a wall curving away from the edge
    # touched it there, and its face cells hold that wall.
    tangents.add([1.3, 1.7], [0.5, 0.5], [-math.pi / 2] * 2, [0.45, 0.45])
    assert not kept([], 1.525, 0.025)
    mapper.params = mapper.params.model_copy(update={"face_short_ratio": 0.0})
    assert kept([], 1.525, 0.025)


def test_touches_of_a_curved_wall_are_not_taken_for_a_flat_one() -> None:
    """From a row of places 0.5 m above the bottom edge (y = 0), looking down: a flat wall on the
    edge is touched from every place; a round wall of radius 2 m touching the edge at x = 1.5 only
    from the places within 25 cm of that point, and the echoes from beside them fall 2-10 cm short."""
    edge = box_walls((0.0, 0.0, 3.0, 3.0))[3]
    xs = [round(1.0 + 0.05 * i, 2) for i in range(21)]
    flat = TangentLines(HALF, TangentParams())
    flat.add(xs, [0.5] * len(xs), [-math.pi / 2] * len(xs), [0.5] * len(xs))
    round_wall = TangentLines(HALF, TangentParams())
    ranges = [2.0 - math.hypot(x - 1.5, 1.5) for x in xs]  # to the circle about (1.5, 2.0)
    round_wall.add(xs, [0.5] * len(xs), [-math.pi / 2] * len(xs), ranges)
    assert flat.flush_touches(edge, 0.1, 0.3, 0.5) == pytest.approx(flat.touches(edge))
    assert flat.touches(edge) == pytest.approx(xs)
    assert round_wall.touches(edge) == pytest.approx([x for x in xs if abs(x - 1.5) < 0.25])
    assert round_wall.flush_touches(edge, 0.1, 0.3, 0.5).size == 0
    # 12 echoes fell short beside the 9 touches: counted only within reach of the stretch, only up
    # to short_m short, and against the ratio.
    assert round_wall.flush_touches(edge, 0.1, 0.0, 0.5).size == 9
    assert round_wall.flush_touches(edge, 0.02, 0.3, 0.5).size == 9
    assert round_wall.flush_touches(edge, 0.1, 0.3, 12 / 9 + 0.01).size == 9
    assert round_wall.flush_touches(edge, 0.1, 0.3, 12 / 9 - 0.01).size == 0


def test_echoes_past_the_voting_range_touch_a_box_edge_the_close_ones_did_not_reach() -> None:
    """A robot that mapped a wall's floor from 1.8 m away and never drove closer: those echoes do not
    vote for lines, but they touch the edge, and hold its face. Beside a stretch the close echoes
    rejected (a curved wall), they do not."""
    edge = box_walls((0.0, 0.0, 3.0, 3.0))[3]  # y = 0
    xs = [round(0.2 + 0.2 * i, 2) for i in range(13)]  # one sweep every 20 cm
    far = TangentLines(HALF, TangentParams())
    far.add(xs, [1.8] * len(xs), [-math.pi / 2] * len(xs), [1.8] * len(xs))
    assert far.lines() == []  # too far to vote
    assert far.touches(edge) == pytest.approx(xs)
    assert far.flush_touches(edge, 0.1, 0.3, 0.5) == pytest.approx(xs)
    # Past touch_range_m they count for nothing.
    beyond = TangentLines(HALF, TangentParams(touch_range_m=1.7))
    beyond.add(xs, [1.8] * len(xs), [-math.pi / 2] * len(xs), [1.8] * len(xs))
    assert beyond.touches(edge).size == 0
    # Close echoes of a wall curving away from the edge at x = 1.5 (as in the test below) reject
    # their stretch, and the far touches near it go with it; those farther along still count.
    near_xs = [round(1.0 + 0.05 * i, 2) for i in range(21)]
    curved = TangentLines(HALF, TangentParams())
    curved.add(
        near_xs, [0.5] * len(near_xs), [-math.pi / 2] * len(near_xs), [2.0 - math.hypot(x - 1.5, 1.5) for x in near_xs]
    )
    curved.add(xs, [1.8] * len(xs), [-math.pi / 2] * len(xs), [1.8] * len(xs))
    kept = curved.flush_touches(edge, 0.1, 0.3, 0.5)
    assert kept == pytest.approx([x for x in xs if x < 0.7 or x > 2.3])


LEANING_ROOMS = {
    # A left wall 2.4 degrees off the box edge, up to 12 cm inside it.
    "leaning": (
        {
            "boundary": [[4.17, 2.66], [2.63, 4.44], [0.12, 3.8], [0.0, 0.95], [2.99, 0.0]],
            "start": {"x": 1.5, "y": 3.77, "theta_deg": 180.0},
            "obstacles": [
                {"shape": "rect", "center": [0.66, 1.24], "size": [0.93, 0.44], "angle_deg": 0.0},
                {"shape": "circle", "center": [2.54, 0.48], "radius": 0.21},
            ],
        },
        0,
        45.0,  # compared with no leaning walls at all
    ),
    # A top wall 1.2 degrees off the box edge, up to 7 cm inside it.
    "leaning_a_degree": (
        {
            "boundary": [[4.64, 2.36], [4.28, 4.73], [0.97, 4.8], [0.0, 2.37], [0.93, 0.3], [3.76, 0.0]],
            "start": {"x": 2.65, "y": 2.97, "theta_deg": 180.0},
            "obstacles": [{"shape": "rect", "center": [2.85, 1.74], "size": [1.04, 0.57], "angle_deg": 90.0}],
        },
        1,
        1.5,  # compared with the rule as it was: walls within 1.5 degrees were the box's own
    ),
}


@pytest.mark.parametrize("name", sorted(LEANING_ROOMS))
def test_a_wall_leaning_just_inside_the_box_edge_keeps_the_cells_it_clips(name: str) -> None:
    """Generated polygons with a wall leaning a little off the box edge: the cells it clips were
    white, their part behind the wall taken for the box wall's face."""
    from robot.runner import simulate
    from robot.settings import load_run_config
    from robot.world import world_from_dict

    room, seed, before_deg = LEANING_ROOMS[name]
    world = world_from_dict({"name": name, **room}, f"{name}.toml")
    cfg = load_run_config()
    assert cfg.slam.logodds.face_slant_deg < 1.2
    # The face rule alone: walls leaning off the box edge also cut the cells they cross (tested above),
    # which would hide what the face rule does here.
    # So does telling a leaning wall's touches of the edge from a flat wall's (tested above), which
    # already keeps the face cells behind the "leaning" room's wall to their own evidence.
    logodds = cfg.slam.logodds
    logodds = logodds.model_copy(
        update={
            "tangents": logodds.tangents.model_copy(update={"box_lean_min_deg": 45.0}),
            "face_short_ratio": 0.0,
        }
    )
    slam = cfg.slam.model_copy(update={"logodds": logodds})
    off = slam.model_copy(update={"logodds": logodds.model_copy(update={"face_slant_deg": before_deg})})
    kept = simulate(world, cfg.robot, cfg.noise, slam, seed=seed)
    lost = simulate(world, cfg.robot, cfg.noise, off, seed=seed)
    assert kept.trajectory == lost.trajectory  # only the final map changes
    assert kept.metrics.recall > lost.metrics.recall
    assert kept.metrics.f1 > lost.metrics.f1


def test_the_round_rooms_wall_where_it_touches_the_box_is_not_taken_for_the_boxs_face() -> None:
    """The round room touches its box at four points. The echoes that touched the box edges there
    held the face cells free as a box wall's, and the cells the wall runs through read white."""
    from robot.runner import simulate
    from robot.settings import load_run_config
    from robot.world import builtin_worlds, load_world

    world = load_world(builtin_worlds()["roundroom"])
    cfg = load_run_config()
    assert cfg.slam.logodds.face_short_ratio > 0.0 and cfg.slam.logodds.face_min_touches > 0
    off = cfg.slam.model_copy(update={"logodds": cfg.slam.logodds.model_copy(update={"face_short_ratio": 0.0})})
    kept = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=2)
    taken = simulate(world, cfg.robot, cfg.noise, off, seed=2)
    assert kept.trajectory == taken.trajectory  # only the final map changes
    assert kept.metrics.recall > taken.metrics.recall
    assert kept.metrics.precision == taken.metrics.precision == 1.0
    assert kept.metrics.f1 > taken.metrics.f1 + 0.02


def test_trimmed_ends_are_numpys_percentiles() -> None:
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 15, 16, 40, 101):
        for _ in range(20):
            values = rng.normal(0.0, rng.uniform(0.01, 5.0), n)
            for percent in (0.0, 2.5, 5.0, 25.0, 49.0):
                expected = np.percentile(values, [percent, 100.0 - percent])
                assert _trimmed_ends(values, percent) == (float(expected[0]), float(expected[1]))


def _best_turn_one_by_one(lines: TangentLines, theta: float, d: float, free: np.ndarray):
    """The search for the best turned line written one turn at a time over every echo, with
    np.median: what the vectorised search must reproduce exactly."""
    p = lines.params
    best = None
    for th in theta + np.radians(np.arange(-1.0, 1.01, 0.1)):
        inside = _off(th, lines._axis) <= lines.half
        dist = math.cos(th) * lines._x + math.sin(th) * lines._y + lines._r
        near = free & inside & (np.abs(dist - d) <= p.tolerance_m)
        if np.count_nonzero(near) < p.min_votes:
            continue
        centre = float(np.median(dist[near]))
        near = free & inside & (np.abs(dist - centre) <= p.tolerance_m)
        score = float(np.sum(1.0 - ((dist[near] - centre) / p.tolerance_m) ** 2))
        if best is None or score > best[2]:
            best = (float(th), centre, score, near)
    return None if best is None else (best[0], best[1], best[3])


def test_the_search_over_turns_picks_the_line_a_turn_by_turn_search_picks() -> None:
    rng = np.random.default_rng(5)
    lines = TangentLines(HALF, TangentParams(enabled=True))
    walls = ((math.radians(20.0), 2.0), (math.radians(200.0), 1.2), (math.radians(95.0), 1.6))
    for theta, d in walls:
        t = (-math.sin(theta), math.cos(theta))
        places = []
        for s in np.arange(-0.5, 0.51, 0.1):
            for dist in (0.45, 0.7, 0.9):
                foot = (d * math.cos(theta) + s * t[0], d * math.sin(theta) + s * t[1])
                places.append((foot[0] - dist * math.cos(theta), foot[1] - dist * math.sin(theta)))
        lines.add(*_echoes_off_line(theta, d, places, rng, 0.008))
    assert len(lines.lines()) == 3  # (this also gathers the echoes into arrays)
    free = rng.random(lines._r.size) < 0.8  # some echoes already taken by other walls
    tried = 0
    for theta, d in walls:
        for dt, dd in ((0.0, 0.0), (0.01, 0.01), (-0.012, -0.02), (0.004, 0.05), (0.3, 0.0)):
            expected = _best_turn_one_by_one(lines, theta + dt, d + dd, free)
            got = lines._best_turn(theta + dt, d + dd, free)
            if expected is None:
                assert got is None
                continue
            tried += 1
            assert got is not None
            assert got[0] == expected[0] and got[1] == expected[1]
            assert np.array_equal(got[2], expected[2])
    assert tried >= 9


def test_two_lines_are_near_when_they_run_close_over_the_touched_stretch() -> None:
    """A wall found a few degrees off a box edge, far from the origin, runs within centimetres of
    the edge where the echoes touched it although its distance from the origin differs by 26 cm."""
    edge = Line(theta=0.0, d=4.0, s0=-math.inf, s1=math.inf, echoes=0, scatter=0.0)  # x = 4
    theta = math.radians(3.0)
    d = 4.03 * math.cos(theta) + 4.5 * math.sin(theta)  # through (4.03, 4.5)
    seen = Line(theta=theta, d=d, s0=0.0, s1=0.0, echoes=20, scatter=0.01)
    touched = replace(seen, s0=seen.along(4.0563, 4.0), s1=seen.along(4.0038, 5.0))
    turn = math.radians(4.0)
    assert abs(d - edge.d) > 0.25
    assert touched.near(edge, turn, 0.1)
    # The same line touched all the way down to y = 0 runs 27 cm off the edge there.
    assert not replace(touched, s0=touched.along(4.266, 0.0)).near(edge, turn, 0.1)
    # Nor is it near when it turns farther than allowed.
    assert not touched.near(edge, math.radians(2.0), 0.1)
    # A line with no bounded stretch is compared by its distance from the origin.
    assert edge.near(replace(edge, d=4.08), turn, 0.1) and not edge.near(replace(edge, d=4.12), turn, 0.1)


def test_the_strip_in_front_of_a_wall_found_along_an_axis_is_the_walls_face() -> None:
    """Evidence cells whose centres lie between ``inner_face_clear_m`` and ``inner_face_band_m`` in
    front of a wall found along a grid axis, over its touched stretch, are its face: not where the
    two faces of a concave corner meet, nor in front of a wall far off the axes (slanted walls cut
    the cells they cross instead)."""
    from robot.config import RobotConfig
    from robot.mapping.base import MapFrame
    from robot.mapping.logodds import LogOddsMapper, LogOddsParams
    from robot.world import Pose

    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(0.5, 0.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0))
    params = LogOddsParams(inner_face_band_m=0.06, inner_face_clear_m=0.015)
    mapper = LogOddsMapper(frame, RobotConfig(), params)
    f = mapper.fine.resolution  # 5 cm

    def centre_index(x: float, y: float) -> tuple[int, int]:
        r, c = mapper.fine.world_to_index(x, y)
        return int(r) - mapper.pad, int(c) - mapper.pad

    # A face at x = 2.0 (a cell boundary) seen from the room on its left, touched from y = 0.5 to 2.5.
    face = Line(0.0, 2.0, 0.5, 2.5, 50, 0.005)
    strip = mapper._in_front_of_walls([face], [face])
    assert strip[centre_index(2.0 - 0.5 * f, 1.525)]  # the evidence cell just in front: 2.5 cm
    assert not strip[centre_index(2.0 - 1.5 * f, 1.525)]  # 7.5 cm in front: its own evidence decides
    assert not strip[centre_index(2.0 + 0.5 * f, 1.525)]  # behind the face
    assert not strip[centre_index(2.0 - 0.5 * f, 2.825)]  # past the touched stretch
    assert np.count_nonzero(strip) == 2.0 / f  # one evidence cell wide, along the 2 m stretch
    # A face turned by 1 degree: the cells at x = 1.975 lie 1.5 cm in front of it near y = 0.55, and
    # behind it near the stretch's other end.
    tilted = Line(math.radians(1.0), 2.0, 0.5, 2.5, 50, 0.005)
    tilted_strip = mapper._in_front_of_walls([tilted], [tilted])
    assert tilted_strip[centre_index(2.0 - 0.5 * f, 0.575)] and not tilted_strip[centre_index(2.0 - 0.5 * f, 2.475)]
    # A concave corner: a face along y = 2.0 that meets it (a box pushed against it) keeps its own cells.
    other = Line(math.pi / 2, 2.0, -2.0, -1.0, 50, 0.005)  # normal +y, touched from x = 1 to 2
    cornered = mapper._in_front_of_walls([face], [face, other])
    assert not cornered[centre_index(2.0 - 0.5 * f, 2.0 + 0.5 * f)] and cornered[centre_index(2.0 - 0.5 * f, 1.525)]
    # The back face of a 10 cm partition does not shield the strip in front of its front face.
    back = Line(math.pi, -2.1, -2.5, -0.5, 50, 0.005)
    assert np.array_equal(mapper._in_front_of_walls([face], [face, back]), strip)
    slanted = Line(math.radians(20.0), 2.0, 0.5, 2.5, 50, 0.005)
    assert not mapper._in_front_of_walls([slanted], [slanted]).any()


PARTITION_ROOM = {
    # Generated (benchmarks/unseen_rooms.py --seed 2024, room 1): a 10 cm partition with a doorway,
    # its faces on cell boundaries at 0.1 m.
    "boundary": [[6.1, 0.0], [6.1, 4.0], [0.0, 4.0], [0.0, 0.0]],
    "start": {"x": 4.9, "y": 0.95, "theta_deg": -90.0},
    "obstacles": [
        {"shape": "rect", "center": [3.05, 0.4], "size": [0.1, 0.8]},
        {"shape": "rect", "center": [3.05, 2.875], "size": [0.1, 2.25]},
        {"shape": "circle", "center": [2.05, 2.85], "radius": 0.2},
        {"shape": "rect", "center": [1.05, 2.8], "size": [0.6, 0.4], "angle_deg": 0.0},
        {"shape": "rect", "center": [5.75, 0.7], "size": [0.7, 0.4], "angle_deg": 0.0},
    ],
}


def test_cells_in_front_of_a_partitions_faces_on_cell_boundaries_read_free() -> None:
    """At 0.1 m the partition's faces lie on cell boundaries, and the fringes of the echo arcs off
    them marked the column in front of each face black (F1 0.911). The walls found along them say
    where the faces are."""
    from robot.runner import simulate
    from robot.settings import load_run_config
    from robot.world import world_from_dict

    world = world_from_dict({"name": "partition", **PARTITION_ROOM}, "partition.toml")
    cfg = load_run_config(None, {"resolution": 0.1})
    assert cfg.slam.logodds.inner_face_band_m > cfg.slam.logodds.inner_face_clear_m > 0.0
    off = cfg.slam.model_copy(update={"logodds": cfg.slam.logodds.model_copy(update={"inner_face_band_m": 0.0})})
    kept = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    before = simulate(world, cfg.robot, cfg.noise, off, seed=0)
    assert kept.trajectory == before.trajectory  # only the final map changes
    assert kept.metrics.recall == before.metrics.recall
    assert kept.metrics.f1 > before.metrics.f1 + 0.02
